"""Checkpoint and resume of a simulation run (``simulation.checkpoint.h5``).

A checkpoint holds everything the step loop reads and mutates between two jitted chunks, so that a
run resumed from it calls the same kernels with the same arguments at the same step boundaries as
an uninterrupted run and gives the same results bit for bit (same machine, same thread count):

- the State: ``x``, ``q``, ``v``, ``w`` (half-step velocities), ``t``, ``step``, ``acc`` (energy
  accumulators);
- the integrator's mutable arrays: ``strain_prev`` (stiffness-proportional damping), ``drive_v`` and
  the plane pass's (``pl_pos``, ``pl_force``, ``pen_idx``, ``pen_f``: ``terms.planes.CHECKPOINT_FIELDS``);
- the history rows written so far and the row counter, the frames written so far;
- the run's constants that would otherwise be recomputed from the *initial* state: the initial
  kinetic + strain energy (energy reference of the blow-up check and the residual), the origin step;
- each per-step term's ``data``, saved generically as a (nested) tuple of numpy arrays, numbers and
  numba typed lists of arrays (buffers the kernel grows are restored at their grown size), and any
  arrays a term contributes through ``checkpoint_arrays()`` / ``restore_arrays(arrays)`` (an optional
  protocol: a term with Python-side mutable state implements both).

It is an ordinary fiberpipe artifact of kind ``checkpoint`` (written atomically), whose
``config_sha256`` is the simulate stage's cache key (config sections + mesh hash): a resume with a
changed config or mesh is refused.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import FiberpipeError
from .layout import ACC_SIZE

CHECKPOINT_NAME = "simulation.checkpoint.h5"


class SimulationInterrupted(FiberpipeError):
    """The run was stopped by a signal (Ctrl-C / SIGTERM) after writing a checkpoint.

    ``exit_code`` is 128 + the signal number (130 for SIGINT, 143 for SIGTERM).
    """

    exit_code = 130

    def __init__(self, message: str, *, signum: int | None = None, checkpoint=None, where=None):
        super().__init__(message, where=where)
        if signum is not None:
            self.exit_code = 128 + int(signum)
        self.checkpoint = checkpoint


@dataclass
class Checkpoint:
    """The resumable state of a run between two jitted chunks (see the module docstring)."""

    # State
    x: np.ndarray
    q: np.ndarray
    v: np.ndarray
    w: np.ndarray
    acc: np.ndarray
    t: float
    step: int
    # run constants
    origin_step: int
    total_steps: int
    dt_s: float
    history_every: int
    chunk_steps: int
    checkpoint_every: int
    e0_ke: float
    e0_se: float
    wall_time_s: float
    effects: list
    # integrator arrays
    integrator_arrays: dict
    # output so far
    hist: np.ndarray  # (h_row, C)
    frames_time: np.ndarray
    frames_positions: np.ndarray
    frames_rotations: np.ndarray
    # the per-step terms' data (nested tuples of arrays/scalars) by term name, and terms' own arrays
    term_data: dict = field(default_factory=dict)
    effect_arrays: dict = field(default_factory=dict)

    @property
    def h_row(self) -> int:
        return int(self.hist.shape[0])


# -- a term's data: a nested tuple of arrays and scalars <-> flat datasets ---------------------------


def _flatten(obj, prefix: str, out: dict, spec: list):
    """Flatten a nested tuple into ``out`` (name -> array) and a JSON-able ``spec`` of its structure."""
    if isinstance(obj, tuple):
        sub = []
        for i, item in enumerate(obj):
            _flatten(item, f"{prefix}/{i}", out, sub)
        spec.append(["tuple", sub])
    elif _is_typed_list(obj):
        sub = []
        for i, item in enumerate(obj):
            _flatten(item if isinstance(item, tuple) else np.asarray(item), f"{prefix}/{i}", out, sub)
        spec.append(["list", sub])
    elif isinstance(obj, np.ndarray):
        out[prefix] = obj
        spec.append(["array", prefix])
    elif isinstance(obj, (bool, np.bool_)):
        out[prefix] = np.asarray(obj)
        spec.append(["bool", prefix])
    elif isinstance(obj, (int, np.integer)):
        out[prefix] = np.asarray(obj, dtype=np.int64)
        spec.append(["int", prefix])
    elif isinstance(obj, (float, np.floating)):
        out[prefix] = np.asarray(obj, dtype=np.float64)
        spec.append(["float", prefix])
    else:
        raise FiberpipeError(f"checkpoint: a term's data holds a {type(obj).__name__}, which cannot "
                             "be saved (only tuples of numpy arrays and numbers)")


def _is_typed_list(obj) -> bool:
    return type(obj).__name__ == "List" and type(obj).__module__.startswith("numba")


def _unflatten(spec, arrays: dict):
    kind, val = spec
    if kind == "tuple":
        return tuple(_unflatten(s, arrays) for s in val)
    if kind == "list":
        from numba.typed import List

        return List([_unflatten(s, arrays) for s in val])
    a = arrays[val]
    if kind == "array":
        return np.array(a)  # a fresh writable, contiguous copy
    if kind == "bool":
        return bool(a)
    if kind == "int":
        return int(a)
    return float(a)


def restore_into(current, saved):
    """Copy ``saved`` into the arrays of ``current`` in place where shapes and dtypes agree (the jitted
    kernel may hold references to them); return the structure to use from now on (NamedTuples keep
    their type: the saved file holds plain tuples)."""
    if isinstance(current, tuple) and isinstance(saved, tuple) and len(current) == len(saved):
        items = [restore_into(c, s) for c, s in zip(current, saved)]
        return type(current)(*items) if hasattr(current, "_fields") else tuple(items)
    if _is_typed_list(current) and _is_typed_list(saved) and len(current) == len(saved):
        for i in range(len(saved)):  # in place: the buffers may have grown, the list object stays
            cur = current[i]
            if isinstance(cur, tuple):
                current[i] = restore_into(cur, saved[i])
            elif cur.shape == saved[i].shape and cur.dtype == saved[i].dtype:
                np.copyto(cur, saved[i])
            else:
                current[i] = saved[i]
        return current
    if (isinstance(current, np.ndarray) and isinstance(saved, np.ndarray) and current.shape == saved.shape
            and current.dtype == saved.dtype and current.flags.writeable):
        np.copyto(current, saved)
        return current
    return saved


# -- write / read ----------------------------------------------------------------------------------


def write_checkpoint(path: str | Path, ck: Checkpoint, *, config_sha256: str = "", inputs=None) -> Path:
    """Write ``ck`` atomically as a ``checkpoint`` artifact."""
    from ..artifacts import write_artifact

    ds = {
        "state/x": ck.x, "state/q": ck.q, "state/v": ck.v, "state/w": ck.w, "state/acc": ck.acc,
        "history/rows": np.asarray(ck.hist, dtype=np.float64),
        "frames/time": np.asarray(ck.frames_time, dtype=np.float64),
        "frames/positions": np.asarray(ck.frames_positions, dtype=np.float64),
        "frames/rotations": np.asarray(ck.frames_rotations, dtype=np.float64),
    }
    units = {"state/x": "m", "state/v": "m/s", "state/w": "rad/s", "state/acc": "J",
             "frames/time": "s", "frames/positions": "m"}
    for k, a in ck.integrator_arrays.items():
        ds[f"integrator/{k}"] = a
    structures: dict = {}
    for name, data in ck.term_data.items():
        structure: list = []
        _flatten(data, f"terms/{name}", ds, structure)
        structures[name] = structure[0]
    for ename, arrs in ck.effect_arrays.items():
        for k, a in arrs.items():
            ds[f"effects/{ename}/{k}"] = np.asarray(a)
    attrs = {
        "t_s": float(ck.t), "step": int(ck.step), "origin_step": int(ck.origin_step),
        "total_steps": int(ck.total_steps), "dt_s": float(ck.dt_s), "history_every": int(ck.history_every),
        "chunk_steps": int(ck.chunk_steps), "checkpoint_every": int(ck.checkpoint_every),
        "e0_kinetic_J": float(ck.e0_ke), "e0_strain_J": float(ck.e0_se), "wall_time_s": float(ck.wall_time_s),
        "effects": list(ck.effects), "h_row": int(ck.h_row),
        "term_structures": json.dumps(structures),
        "effect_arrays": json.dumps({k: sorted(v) for k, v in ck.effect_arrays.items()}),
    }
    return write_artifact(path, "checkpoint", ds, units=units, attrs=attrs, config_sha256=config_sha256,
                          inputs=inputs)


def read_checkpoint(path: str | Path, *, config_sha256: str | None = None) -> Checkpoint:
    """Read a checkpoint; with ``config_sha256``, refuse one written for another config or mesh."""
    from ..artifacts import read_artifact
    from ..errors import ArtifactError

    art = read_artifact(path, "checkpoint")
    a = art.attrs
    if config_sha256 is not None and a.get("config_sha256") != config_sha256:
        raise ArtifactError(
            "was written for a different config or mesh (the material, scene, solver sections, mesh.h5 or "
            "the solver's code changed since), so the run cannot be resumed from it; rerun with --force to "
            "discard it and start over", where=str(path))
    if art["state/acc"].shape != (ACC_SIZE,):
        raise ArtifactError(
            f"was written by a version of fiberpipe with {art['state/acc'].shape[0]} energy accumulators (this one "
            f"keeps {ACC_SIZE}), so the run cannot be resumed from it; rerun with --force to start over", where=str(path))
    try:
        terms = {name: _unflatten(structure, art.data)
                 for name, structure in json.loads(a.get("term_structures", "{}")).items()}
        eff = {}
        for ename, keys in json.loads(a.get("effect_arrays", "{}")).items():
            eff[ename] = {k: art[f"effects/{ename}/{k}"] for k in keys}
        arrays = {k[len("integrator/"):]: v for k, v in art.data.items() if k.startswith("integrator/")}
        return Checkpoint(
            x=art["state/x"], q=art["state/q"], v=art["state/v"], w=art["state/w"], acc=art["state/acc"],
            t=float(a["t_s"]), step=int(a["step"]), origin_step=int(a["origin_step"]),
            total_steps=int(a["total_steps"]), dt_s=float(a["dt_s"]), history_every=int(a["history_every"]),
            chunk_steps=int(a["chunk_steps"]), checkpoint_every=int(a["checkpoint_every"]),
            e0_ke=float(a["e0_kinetic_J"]), e0_se=float(a["e0_strain_J"]), wall_time_s=float(a["wall_time_s"]),
            effects=json.loads(a["effects"]) if isinstance(a["effects"], str) else list(a["effects"]),
            integrator_arrays=arrays, hist=art["history/rows"], frames_time=art["frames/time"],
            frames_positions=art["frames/positions"], frames_rotations=art["frames/rotations"],
            term_data=terms, effect_arrays=eff,
        )
    except (KeyError, ValueError, TypeError) as exc:
        raise ArtifactError(f"is an incomplete or damaged checkpoint ({exc})", where=str(path)) from None
