"""A checker of Abaqus input-file syntax, written from the Abaqus keyword reference independently of
fiberpipe's writer: every keyword known and at the right level (part, assembly, model, step),
required parameters present and parameter values allowed, data lines of the right shape, and every
node set, element set, surface, material, interaction and amplitude defined before it is used.

``check(text)`` returns a list of problems (empty: the deck passes) and the parsed model.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

# keyword: (required parameters, allowed parameters, levels where it may appear)
# levels: "model" (top level, outside part/assembly/step), "part", "assembly", "step"
K = {
    "HEADING": ((), (), {"model"}),
    "PREPRINT": ((), ("ECHO", "MODEL", "HISTORY", "CONTACT"), {"model"}),
    "PART": (("NAME",), ("NAME",), {"model"}),
    "END PART": ((), (), {"part"}),
    "ASSEMBLY": (("NAME",), ("NAME",), {"model"}),
    "END ASSEMBLY": ((), (), {"assembly"}),
    "INSTANCE": (("NAME", "PART"), ("NAME", "PART"), {"assembly"}),
    "END INSTANCE": ((), (), {"instance"}),
    "NODE": ((), ("NSET",), {"part", "assembly"}),
    "ELEMENT": (("TYPE",), ("TYPE", "ELSET"), {"part"}),
    "NSET": (("NSET",), ("NSET", "GENERATE", "INSTANCE"), {"part", "assembly"}),
    "ELSET": (("ELSET",), ("ELSET", "GENERATE", "INSTANCE"), {"part", "assembly"}),
    "BEAM SECTION": (("ELSET", "MATERIAL", "SECTION"), ("ELSET", "MATERIAL", "SECTION"), {"part"}),
    "SURFACE": (("NAME",), ("NAME", "TYPE"), {"part", "assembly"}),
    "RIGID BODY": (("REF NODE",), ("REF NODE", "ANALYTICAL SURFACE", "ELSET"), {"assembly"}),
    "MATERIAL": (("NAME",), ("NAME",), {"model"}),
    "ELASTIC": ((), ("TYPE",), {"material"}),
    "DENSITY": ((), (), {"material"}),
    "DAMPING": ((), ("ALPHA", "BETA"), {"material"}),
    "SURFACE INTERACTION": (("NAME",), ("NAME",), {"model"}),
    "FRICTION": ((), (), {"interaction"}),
    "SURFACE BEHAVIOR": ((), ("PRESSURE-OVERCLOSURE",), {"interaction"}),
    "AMPLITUDE": (("NAME",), ("NAME", "DEFINITION", "TIME"), {"model"}),
    "STEP": ((), ("NAME", "NLGEOM"), {"model"}),
    "END STEP": ((), (), {"step"}),
    "DYNAMIC": (("EXPLICIT",), ("EXPLICIT", "SCALE FACTOR", "DIRECT USER CONTROL"), {"step"}),
    "FIXED MASS SCALING": ((), ("FACTOR", "ELSET", "TYPE"), {"step"}),
    "BOUNDARY": ((), ("TYPE", "AMPLITUDE", "OP"), {"step"}),
    "CLOAD": ((), ("AMPLITUDE", "OP"), {"step"}),
    "DLOAD": ((), ("AMPLITUDE", "OP"), {"step"}),
    "CONTACT": ((), (), {"step"}),
    "CONTACT INCLUSIONS": ((), ("ALL EXTERIOR",), {"contact"}),
    "CONTACT PROPERTY ASSIGNMENT": ((), (), {"contact"}),
    "OUTPUT": ((), ("FIELD", "HISTORY", "TIME INTERVAL", "NUMBER INTERVAL"), {"step"}),
    "ENERGY OUTPUT": ((), ("ELSET", "VARIABLE"), {"output"}),
    "NODE OUTPUT": ((), ("NSET",), {"output"}),
}
VALUES = {
    ("ELEMENT", "TYPE"): {"B31", "B31H", "B32"},
    ("BEAM SECTION", "SECTION"): {"CIRC", "PIPE", "RECT"},
    ("SURFACE", "TYPE"): {"ELEMENT", "NODE", "CYLINDER", "SEGMENTS", "REVOLUTION"},
    ("AMPLITUDE", "DEFINITION"): {"TABULAR", "SMOOTH STEP", "EQUALLY SPACED", "PERIODIC"},
    ("BOUNDARY", "TYPE"): {"DISPLACEMENT", "VELOCITY", "ACCELERATION"},
    ("SURFACE BEHAVIOR", "PRESSURE-OVERCLOSURE"): {"HARD", "TABULAR", "EXPONENTIAL", "LINEAR"},
    ("STEP", "NLGEOM"): {"YES", "NO"},
}
ENERGIES = {"ALLKE", "ALLSE", "ALLPW", "ALLFD", "ALLVD", "ALLWK", "ALLIE", "ETOTAL", "ALLAE", "ALLCD", "ALLMW"}
NODE_OUTPUTS = re.compile(r"^(U|V|A|RF|UR|VR|RM|COORD)[1-6]?$")
# sub-options: the keyword that opens the block they belong to
OPENS = {"MATERIAL": "material", "SURFACE INTERACTION": "interaction", "CONTACT": "contact", "OUTPUT": "output",
         "INSTANCE": "instance"}


@dataclass
class Keyword:
    name: str
    params: dict
    data: list = field(default_factory=list)
    line: int = 0


def parse(text: str) -> list[Keyword]:
    """Keyword lines (``*NAME, P=V, FLAG``) with their data lines; ``**`` lines are comments."""
    out: list[Keyword] = []
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.rstrip()
        if not line or line.startswith("**"):
            continue
        if line.startswith("*"):
            parts = [p.strip() for p in line[1:].split(",")]
            params = {}
            for p in parts[1:]:
                if p:
                    k, _, v = p.partition("=")
                    params[k.strip().upper()] = v.strip() if _ else True
            out.append(Keyword(parts[0].upper(), params, [], n))
        elif out:
            out[-1].data.append((n, [c.strip() for c in line.split(",")]))
        else:
            out.append(Keyword("?", {}, [(n, [line])], n))
    return out


def _float(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


@dataclass
class Model:
    parts: dict = field(default_factory=dict)  # part -> {"nodes": set, "nsets": {name: set}, "elsets": {...}, "surfaces": set}
    instances: dict = field(default_factory=dict)  # instance -> part
    assembly: dict = field(default_factory=lambda: {"nodes": set(), "nsets": {}, "elsets": {}, "surfaces": set()})
    materials: set = field(default_factory=set)
    interactions: set = field(default_factory=set)
    amplitudes: dict = field(default_factory=dict)  # name -> [(t, a)]
    keywords: list = field(default_factory=list)


def _new_scope():
    return {"nodes": set(), "nsets": {}, "elsets": {}, "surfaces": set(), "elements": {}}


def check(text: str) -> tuple[list[str], Model]:
    kws = parse(text)
    model = Model(keywords=kws)
    problems: list[str] = []
    err = lambda kw, msg: problems.append(f"line {kw.line} *{kw.name}: {msg}")  # noqa: E731

    for n, raw in enumerate(text.splitlines(), 1):
        if len(raw) > 256:
            problems.append(f"line {n}: longer than 256 characters")
    # names defined anywhere in model data may be referenced before their definition (Abaqus reads
    # the model data as a whole); sets and surfaces must come before their use
    model.materials = {k.params.get("NAME") for k in kws if k.name == "MATERIAL"}

    level, block, part, scope = "model", None, None, None
    seen_step = False
    for kw in kws:
        if kw.name not in K:
            err(kw, "unknown keyword")
            continue
        req, allowed, levels = K[kw.name]
        here = block if kw.name in {"ELASTIC", "DENSITY", "DAMPING", "FRICTION", "SURFACE BEHAVIOR",
                                    "CONTACT INCLUSIONS", "CONTACT PROPERTY ASSIGNMENT", "ENERGY OUTPUT",
                                    "NODE OUTPUT", "END INSTANCE"} else level
        if here not in levels:
            err(kw, f"not allowed here ({here or level})")
        for r in req:
            if r not in kw.params:
                err(kw, f"required parameter {r} missing")
        for p, v in kw.params.items():
            if p not in allowed:
                err(kw, f"unknown parameter {p}")
            if (kw.name, p) in VALUES and v not in VALUES[(kw.name, p)]:
                err(kw, f"{p}={v} is not one of {sorted(VALUES[(kw.name, p)])}")
        # block bookkeeping
        if kw.name in OPENS:
            block = OPENS[kw.name]
        elif kw.name not in {"ELASTIC", "DENSITY", "DAMPING", "FRICTION", "SURFACE BEHAVIOR", "CONTACT INCLUSIONS",
                             "CONTACT PROPERTY ASSIGNMENT", "ENERGY OUTPUT", "NODE OUTPUT", "END INSTANCE"}:
            block = None
        if kw.name == "PART":
            level, part = "part", kw.params.get("NAME")
            scope = model.parts.setdefault(part, _new_scope())
        elif kw.name == "END PART":
            level, part, scope = "model", None, None
        elif kw.name == "ASSEMBLY":
            level, scope = "assembly", model.assembly
            scope.setdefault("elements", {})
        elif kw.name == "END ASSEMBLY":
            level, scope = "model", None
        elif kw.name == "INSTANCE":
            if kw.params.get("PART") not in model.parts:
                err(kw, f"part {kw.params.get('PART')} not defined before")
            model.instances[kw.params.get("NAME")] = kw.params.get("PART")
        elif kw.name == "STEP":
            if seen_step:
                err(kw, "more than one step")
            level, seen_step = "step", True
        elif kw.name == "END STEP":
            level = "model"
        _check_data(kw, model, scope, err)
    if level != "model":
        problems.append(f"end of file inside a {level} (missing *END {level.upper()})")
    if not seen_step:
        problems.append("no *STEP")
    return problems, model


# -- references ------------------------------------------------------------------------------------

def _resolve_nset(model: Model, scope, name: str):
    """The node labels of ``name`` (a set, ``INSTANCE.SET``, ``INSTANCE.LABEL`` or a label)."""
    if "." in name:
        inst, _, rest = name.partition(".")
        part = model.parts.get(model.instances.get(inst))
        if part is None:
            return None
        if rest.isdigit():
            return {int(rest)} if int(rest) in part["nodes"] else None
        return part["nsets"].get(rest)
    if name.isdigit():
        return {int(name)} if scope and int(name) in scope["nodes"] else None
    for sc in (scope, model.assembly):
        if sc and name in sc["nsets"]:
            return sc["nsets"][name]
    return None


def _resolve(model: Model, scope, name: str, kind: str) -> bool:
    if "." in name:
        inst, _, rest = name.partition(".")
        part = model.parts.get(model.instances.get(inst))
        return part is not None and (rest in part[kind] if kind != "elsets" else rest in part["elsets"])
    return any(sc and name in sc[kind] for sc in (scope, model.assembly))


def _check_data(kw: Keyword, model: Model, scope, err) -> None:
    rows = kw.data
    name = kw.name
    if name == "NODE":
        for n, r in rows:
            if len(r) < 4 or not r[0].isdigit() or not all(_float(x) for x in r[1:4]):
                err(kw, f"line {n}: a node is 'label, x, y, z'")
                continue
            if int(r[0]) in scope["nodes"]:
                err(kw, f"line {n}: node {r[0]} defined twice")
            scope["nodes"].add(int(r[0]))
    elif name == "ELEMENT":
        labels = set()
        for n, r in rows:
            if len(r) != 3 or not all(x.isdigit() for x in r):
                err(kw, f"line {n}: a B31 element is 'label, node1, node2'")
                continue
            if int(r[0]) in scope["elements"]:
                err(kw, f"line {n}: element {r[0]} defined twice")
            for x in r[1:]:
                if int(x) not in scope["nodes"]:
                    err(kw, f"line {n}: node {x} not defined before")
            scope["elements"][int(r[0])] = (int(r[1]), int(r[2]))
            labels.add(int(r[0]))
        if "ELSET" in kw.params:
            scope["elsets"].setdefault(kw.params["ELSET"], set()).update(labels)
    elif name in ("NSET", "ELSET"):
        target = kw.params.get(name)
        members: set = set()
        inst = kw.params.get("INSTANCE")
        pool = scope["nodes"] if name == "NSET" else set(scope["elements"])
        if inst is not None:
            part = model.parts.get(model.instances.get(inst))
            if part is None:
                err(kw, f"instance {inst} not defined before")
                return
            pool = part["nodes"] if name == "NSET" else set(part["elements"])
        for n, r in rows:
            r = [x for x in r if x]
            if kw.params.get("GENERATE"):
                if len(r) != 3 or not all(x.isdigit() for x in r):
                    err(kw, f"line {n}: GENERATE takes 'first, last, step'")
                    continue
                members.update(range(int(r[0]), int(r[1]) + 1, int(r[2])))
            else:
                for x in r:
                    if x.isdigit():
                        members.add(int(x))
                    elif name == "ELSET" and x in scope["elsets"]:
                        members.update(scope["elsets"][x])
                    elif name == "NSET" and x in scope["nsets"]:
                        members.update(scope["nsets"][x])
                    else:
                        err(kw, f"line {n}: {x} is neither a label nor a set defined before")
        missing = members - pool
        if missing:
            err(kw, f"{len(missing)} labels not defined before (e.g. {sorted(missing)[:3]})")
        key = "nsets" if name == "NSET" else "elsets"
        scope[key].setdefault(target, set()).update(members)
    elif name == "BEAM SECTION":
        if kw.params.get("ELSET") not in scope["elsets"]:
            err(kw, f"element set {kw.params.get('ELSET')} not defined before")
        if kw.params.get("MATERIAL") not in model.materials:
            err(kw, f"material {kw.params.get('MATERIAL')} not defined in the model")
        if len(rows) != 2 or len(rows[0][1]) < 1 or not _float(rows[0][1][0]) or float(rows[0][1][0]) <= 0:
            err(kw, "SECTION=CIRC takes the radius (> 0), then the n1 direction")
        elif len(rows[1][1]) != 3 or not all(_float(x) for x in rows[1][1]):
            err(kw, "the second data line is the n1 direction (3 components)")
    elif name == "SURFACE":
        sname = kw.params.get("NAME")
        typ = kw.params.get("TYPE", "ELEMENT")
        if typ == "ELEMENT":
            for n, r in rows:
                if not _resolve(model, scope, r[0], "elsets"):
                    err(kw, f"line {n}: element set {r[0]} not defined before")
        elif typ == "CYLINDER":
            ok = (len(rows) >= 4 and len(rows[0][1]) == 6 and all(_float(x) for x in rows[0][1])
                  and len(rows[1][1]) == 3 and all(_float(x) for x in rows[1][1])
                  and rows[2][1][0].upper() == "START" and len(rows[2][1]) == 3
                  and all(r[0].upper() in ("LINE", "CIRCL", "PARAB") for _, r in rows[3:]))
            if not ok:
                err(kw, "TYPE=CYLINDER takes a, b (6 numbers), c (3), START x, y, then LINE/CIRCL/PARAB segments")
        scope["surfaces"].add(sname)
    elif name == "RIGID BODY":
        ref = _resolve_nset(model, None, kw.params.get("REF NODE", ""))
        if ref is None:
            err(kw, f"reference node set {kw.params.get('REF NODE')} not defined before")
        elif len(ref) != 1:
            err(kw, f"reference node set {kw.params.get('REF NODE')} must hold exactly one node")
        surf = kw.params.get("ANALYTICAL SURFACE")
        if surf is not None and surf not in scope["surfaces"]:
            err(kw, f"surface {surf} not defined before")
    elif name in ("ELASTIC", "DENSITY"):
        need = 2 if name == "ELASTIC" else 1
        if len(rows) != 1 or len(rows[0][1]) < need or not all(_float(x) for x in rows[0][1][:need]):
            err(kw, f"takes one data line of {need} number(s)")
    elif name == "DAMPING":
        if not ({"ALPHA", "BETA"} & set(kw.params)):
            err(kw, "needs ALPHA or BETA")
        for p in ("ALPHA", "BETA"):
            if p in kw.params and not (_float(kw.params[p]) and float(kw.params[p]) >= 0):
                err(kw, f"{p} must be a number >= 0")
    elif name == "SURFACE INTERACTION":
        model.interactions.add(kw.params.get("NAME"))
    elif name == "FRICTION":
        if len(rows) != 1 or not _float(rows[0][1][0]) or float(rows[0][1][0]) < 0:
            err(kw, "takes the friction coefficient (>= 0)")
    elif name == "SURFACE BEHAVIOR" and kw.params.get("PRESSURE-OVERCLOSURE") == "TABULAR":
        pts = [(float(r[0]), float(r[1])) for _, r in rows if len(r) == 2 and all(_float(x) for x in r)]
        if len(pts) != len(rows) or len(pts) < 2:
            err(kw, "TABULAR takes at least two 'pressure, overclosure' rows")
        elif pts[0][0] != 0 or any(b[1] <= a[1] for a, b in zip(pts, pts[1:])) or any(b[0] < a[0] for a, b in zip(pts, pts[1:])):
            err(kw, "TABULAR: zero pressure first, overclosure increasing, pressure not decreasing")
    elif name == "AMPLITUDE":
        vals = [x for _, r in rows for x in r if x]
        if any(len([x for x in r if x]) > 8 for _, r in rows):
            err(kw, "more than 8 entries on a data line")
        if len(vals) % 2 or not all(_float(x) for x in vals) or len(vals) < 4:
            err(kw, "takes (time, value) pairs, at least two")
        else:
            pts = [(float(vals[i]), float(vals[i + 1])) for i in range(0, len(vals), 2)]
            if any(b[0] <= a[0] for a, b in zip(pts, pts[1:])):
                err(kw, "times must increase")
            model.amplitudes[kw.params.get("NAME")] = pts
    elif name == "DYNAMIC":
        if len(rows) != 1 or len(rows[0][1]) < 2 or not _float(rows[0][1][1]) or float(rows[0][1][1]) <= 0:
            err(kw, "EXPLICIT takes ', time period' (> 0)")
        sf = kw.params.get("SCALE FACTOR")
        if sf is not None and not (_float(sf) and 0 < float(sf) <= 1):
            err(kw, "SCALE FACTOR must be in (0, 1]")
    elif name in ("BOUNDARY", "CLOAD"):
        amp = kw.params.get("AMPLITUDE")
        if amp is not None and amp not in model.amplitudes:
            err(kw, f"amplitude {amp} not defined before")
        for n, r in rows:
            if _resolve_nset(model, model.assembly, r[0]) is None:
                err(kw, f"line {n}: node set {r[0]} not defined before")
            if name == "BOUNDARY" and len(r) == 2 and r[1].upper() in ("ENCASTRE", "PINNED", "XSYMM", "YSYMM", "ZSYMM"):
                continue
            dofs = r[1:3] if name == "BOUNDARY" else r[1:2]
            if not dofs or not all(x.isdigit() and 1 <= int(x) <= 6 for x in dofs):
                err(kw, f"line {n}: degrees of freedom must be 1–6")
            if name == "BOUNDARY" and len(dofs) == 2 and int(dofs[0]) > int(dofs[1]):
                err(kw, f"line {n}: first DOF after last")
            if name == "CLOAD" and (len(r) != 3 or not _float(r[2])):
                err(kw, f"line {n}: 'node, dof, magnitude'")
    elif name == "DLOAD":
        for n, r in rows:
            if not _resolve(model, model.assembly, r[0], "elsets"):
                err(kw, f"line {n}: element set {r[0]} not defined before")
            if len(r) < 3 or r[1].upper() not in ("GRAV", "PX", "PY", "PZ") or not _float(r[2]):
                err(kw, f"line {n}: 'elset, GRAV|PX|PY|PZ, magnitude[, direction]'")
            if r[1].upper() == "GRAV" and (len(r) != 6 or not all(_float(x) for x in r[3:6])):
                err(kw, f"line {n}: GRAV takes a magnitude and a direction (3 components)")
    elif name == "CONTACT INCLUSIONS":
        for n, r in rows:
            for s in r[:2]:
                if s and not _resolve(model, model.assembly, s, "surfaces"):
                    err(kw, f"line {n}: surface {s} not defined before")
        if not kw.params.get("ALL EXTERIOR") and not rows:
            err(kw, "needs ALL EXTERIOR or surface pairs")
    elif name == "CONTACT PROPERTY ASSIGNMENT":
        for n, r in rows:
            for s in r[:2]:
                if s and not _resolve(model, model.assembly, s, "surfaces"):
                    err(kw, f"line {n}: surface {s} not defined before")
            if len(r) < 3 or r[2] not in model.interactions:
                err(kw, f"line {n}: interaction {r[2] if len(r) > 2 else '?'} not defined before")
    elif name == "OUTPUT":
        if bool(kw.params.get("FIELD")) == bool(kw.params.get("HISTORY")):
            err(kw, "needs exactly one of FIELD and HISTORY")
    elif name == "ENERGY OUTPUT":
        for n, r in rows:
            bad = [x for x in r if x and x not in ENERGIES]
            if bad:
                err(kw, f"line {n}: unknown energy variables {bad}")
    elif name == "NODE OUTPUT":
        ns = kw.params.get("NSET")
        if ns is not None and _resolve_nset(model, model.assembly, ns) is None:
            err(kw, f"node set {ns} not defined before")
        for n, r in rows:
            bad = [x for x in r if x and not NODE_OUTPUTS.match(x)]
            if bad:
                err(kw, f"line {n}: unknown node output variables {bad}")
