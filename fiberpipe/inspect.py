"""``fiberpipe inspect``: what an artifact is, where it came from, and what it holds."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from fiberpipe.artifacts import SCHEMA_VERSIONS, file_sha256, open_checked, read_fibers, read_mesh
from fiberpipe.errors import ArtifactError, FiberpipeError


# artifact kinds whose layout --check verifies with the reader the stages use
_LAYOUT_READERS = {"fibers": read_fibers, "mesh": read_mesh}


def inspect_artifact(path: Path, *, check: bool = False, echo=print) -> bool:
    """Print an artifact's root attributes and datasets; with ``check``, read every dataset.

    Returns False when the check finds a problem.
    """
    with open_checked(path, tuple(SCHEMA_VERSIONS)) as f:
        echo(f"{path}")
        for k in sorted(f.attrs):
            v = f.attrs[k]
            v = v.decode() if isinstance(v, bytes) else v
            if k == "inputs":
                v = json.loads(v)
            echo(f"  {k}: {v}")
        ok = True

        def show(name, obj):
            nonlocal ok
            if isinstance(obj, h5py.Dataset):
                units = obj.attrs.get("units", "")
                line = f"  /{name}: {obj.dtype} {obj.shape}" + (f" [{units}]" if units else "")
                if check:
                    try:
                        data = obj[()]
                        if np.issubdtype(obj.dtype, np.floating) and data.size and not np.all(np.isfinite(data)):
                            line += "  (contains NaN/inf)"
                    except OSError:
                        line += "  DAMAGED"
                        ok = False
                echo(line)

        f.visititems(show)
        inputs = f.attrs.get("inputs", "{}")
        inputs = json.loads(inputs.decode() if isinstance(inputs, bytes) else inputs)
        kind = f.attrs.get("kind", "")
        kind = kind.decode() if isinstance(kind, bytes) else kind
    if check and ok and kind in _LAYOUT_READERS:
        # the stages' own reader: the same layout checks (shapes, offsets, finite positions) as a run
        try:
            _LAYOUT_READERS[kind](path)
            echo(f"  layout: a valid {kind} artifact")
        except FiberpipeError as exc:
            echo(f"  layout: {exc}")
            ok = False
    if check:
        # Provenance: an input artifact that sits beside this one must still have the recorded hash.
        for name, digest in inputs.items():
            sibling = path.parent / f"{name}.h5"
            if sibling.exists():
                now = file_sha256(sibling)
                same = now == digest
                ok &= same
                echo(f"  input {name}: {sibling.name} " + ("matches its recorded sha256" if same else "CHANGED since this artifact was made (stale)"))
            else:
                echo(f"  input {name}: not beside this artifact, hash not checked")
        echo("  check: " + ("ok" if ok else "FAILED"))
    return ok
