"""Versioned HDF5 artifacts (docs/outputs.md).

Every artifact is one HDF5 file whose root attributes say what it is (``kind``,
``schema_version``) and where it came from (``fiberpipe_version``, ``created_utc``,
``config_sha256``, ``inputs``: JSON of the sha256 of each input artifact). Every dataset carries a
``units`` attribute: an SI symbol, ``"1"`` when dimensionless, ``"index"`` for offsets and
connectivity, ``"voxel"`` for voxel radii. Writes are atomic: the file is written under a temporary name in the same
folder and renamed over the target, so a crash never leaves a half-written artifact that a later
stage trusts. Readers refuse a wrong kind or an unknown schema version.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import math
import os
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import h5py
import numpy as np

from fiberpipe import __version__
from fiberpipe.errors import ArtifactError, InputError

#: Schema version of each artifact kind this fiberpipe writes and reads.
SCHEMA_VERSIONS = {
    "volume": 1,
    "mask": 1,
    "skeleton": 1,
    "fibers": 1,
    "mesh": 1,
    "simulation": 1,
    "checkpoint": 1,
}


#: ``units`` of a dimensionless dataset (counts, flags, ratios), as in UDUNITS/CF.
DIMENSIONLESS = "1"
#: ``units`` of a dataset of indices into another dataset (offsets, connectivity, fiber ids).
INDEX = "index"

#: Units of the datasets of the volume-like artifacts (:func:`write_volume`).
VOLUME_UNITS = {
    "volume": DIMENSIONLESS,  # grey values, as scanned
    "mask": DIMENSIONLESS,  # boolean: fiber voxel or not
    "skeleton": DIMENSIONLESS,  # boolean: skeleton voxel or not
    "radius_vox": "voxel",  # distance-transform radius, in voxels
}


@dataclass
class Artifact:
    """An artifact read into memory: root attributes and datasets by path."""

    path: Path
    attrs: dict[str, Any]
    data: dict[str, np.ndarray] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    group_attrs: dict[str, dict[str, Any]] = field(default_factory=dict)

    @property
    def kind(self) -> str:
        return self.attrs["kind"]

    def __getitem__(self, name: str) -> np.ndarray:
        name = name.strip("/")
        if name not in self.data:
            raise ArtifactError(f"has no dataset /{name}", where=str(self.path))
        return self.data[name]

    def __contains__(self, name: str) -> bool:
        return name.strip("/") in self.data

    @property
    def inputs(self) -> dict[str, str]:
        return json.loads(self.attrs.get("inputs", "{}"))


def file_sha256(path: str | Path, chunk: int = 1 << 20) -> str:
    """sha256 of a file's bytes."""
    h = hashlib.sha256()
    _update_with_file(h, path, chunk)
    return h.hexdigest()


def _update_with_file(h, path: str | Path, chunk: int = 1 << 20) -> None:
    with open(path, "rb") as f:
        while True:
            b = f.read(chunk)
            if not b:
                break
            h.update(b)


def _input_files(path: Path) -> list[tuple[str, Path]]:
    """The files whose bytes make up the input ``path``, each with the name it is hashed under: the
    file itself; a MetaImage header with its separate data file (``ElementDataFile``); every file
    of a folder (a TIFF stack, a Zarr store), by relative path in sorted order."""
    if path.is_dir():
        return [(f.relative_to(path).as_posix(), f) for f in sorted(path.rglob("*")) if f.is_file()]
    files = [(path.name, path)]
    if path.suffix.lower() == ".mhd":
        try:
            from fiberpipe.imaging.readers.metaimage import read_header

            src = read_header(path)[0].get("ElementDataFile", "LOCAL")
        except Exception:  # noqa: BLE001 — a broken header is reported by the reader, not here
            src = "LOCAL"
        data = path.parent / src
        if src.upper() != "LOCAL" and data.is_file():
            files.append((src, data))
    return files


_INPUT_HASHES: dict = {}


def input_sha256(path: str | Path) -> str | None:
    """sha256 of an input as a stage reads it (:func:`_input_files`: a file, a MetaImage pair, or a
    folder's files with their relative names), None when it does not exist. Remembered per process
    under the files' sizes and modification times, so the cache key and the provenance record of one
    run read a large volume once."""
    path = Path(path)
    if not path.exists():
        return None
    files = _input_files(path)
    sig = (str(path.resolve()), tuple((name, file_stat.st_size, file_stat.st_mtime_ns) for name, file_stat in ((n, f.stat()) for n, f in files)))
    if sig not in _INPUT_HASHES:
        if path.is_file() and len(files) == 1:
            digest = file_sha256(path)  # a single file: its plain sha256, as ``sha256sum`` prints it
        else:
            h = hashlib.sha256()
            for name, f in files:
                h.update(name.encode() + b"\0")
                _update_with_file(h, f)
            digest = h.hexdigest()
        if len(_INPUT_HASHES) >= 16:  # the inputs of the current stages are what is asked again
            _INPUT_HASHES.clear()
        _INPUT_HASHES[sig] = digest
    return _INPUT_HASHES[sig]


def _current_umask() -> int:
    """The process umask, read without changing it where the OS allows (Linux: /proc/self/status).

    Elsewhere it is read by setting and restoring it (``os.umask`` has no read-only form).
    """
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextmanager
def atomic_path(path: str | Path, suffix: str = "") -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it over ``path`` only if the block succeeds.

    The temporary file is created private (``mkstemp``: mode 0600); before the rename it gets the
    mode a plain ``open(path, "w")`` would give, ``0666 & ~umask`` (0644 under the usual umask
    022), so artifacts are readable by whoever may read the run folder.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix + ".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_current_umask())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def write_text_atomic(path: str | Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def ensure_output_dir(path: str | Path, option: str = "--out") -> Path:
    """Create the output folder ``path`` if needed and check a file can be written in it, before
    anything runs; an InputError says why not (an impossible path, a read-only folder) and names
    ``option``, the command option that chose the folder."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".fiberpipe-write-test.", dir=path)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise InputError(f"output folder {path} is not writable: {reason}; choose another {option}") from None
    return path


def _json_key(k) -> str:
    """A mapping key as JSON writes it (``true``, ``null``, numbers as their text)."""
    if isinstance(k, np.generic):
        k = k.item()
    if isinstance(k, bool) or k is None:
        return json.dumps(k)
    return k if isinstance(k, str) else str(k)


def _strict_json(obj):
    """``obj`` with numpy scalars and arrays as Python numbers and lists, sets as sorted lists, NaN
    and ±inf as None, and any other value JSON has no type for as its text."""
    if isinstance(obj, dict):
        out = {}
        for k, v in obj.items():
            key = _json_key(k)
            if key in out:
                raise ValueError(f"two keys of one mapping are both {key!r} in JSON")
            out[key] = _strict_json(v)
        return out
    if isinstance(obj, (list, tuple)):
        return [_strict_json(v) for v in obj]
    if isinstance(obj, (set, frozenset)):
        return [_strict_json(v) for v in sorted(obj)]
    if isinstance(obj, np.ndarray):
        return _strict_json(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if obj is None or isinstance(obj, (bool, int, str)):
        return obj
    return str(obj)


def json_text(obj, *, indent: int | None = 2) -> str:
    """``obj`` as strict JSON (RFC 8259), the text of every JSON file fiberpipe writes: a figure that
    could not be computed (NaN, ±inf, for which JSON has no literal) is written as ``null``, so any
    JSON parser reads the file; numpy values are written as numbers and lists."""
    return json.dumps(_strict_json(obj), indent=indent, allow_nan=False) + "\n"


def write_json_atomic(path: str | Path, obj) -> None:
    """``obj`` as strict JSON (:func:`json_text`), written atomically to ``path``."""
    write_text_atomic(path, json_text(obj))


#: target size of one HDF5 chunk (bytes): h5py's advice is 10 KiB – 1 MiB
CHUNK_BYTES = 1 << 20


def chunk_shape(shape: tuple[int, ...], itemsize: int, target_bytes: int = CHUNK_BYTES) -> tuple[int, ...]:
    """HDF5 chunks along the first axis (a frame, a history row): one row per chunk when a row
    holds ``target_bytes`` or more (its later axes cut to fit), else as many rows as fit; so a
    frame of a (frames, nodes, 3) series reads without decompressing the others."""
    row = int(np.prod(shape[1:], dtype=np.int64)) * itemsize
    if len(shape) == 1 or row < target_bytes:
        rows = max(1, min(shape[0], target_bytes // max(row, itemsize)))
        return (rows, *shape[1:])
    rest = list(shape[1:])
    while int(np.prod(rest, dtype=np.int64)) * itemsize > target_bytes and rest[0] > 1:
        rest[0] = (rest[0] + 1) // 2
    return (1, *rest)


def write_artifact(
    path: str | Path,
    kind: str,
    datasets: dict[str, Any],
    *,
    units: dict[str, str] | None = None,
    attrs: dict[str, Any] | None = None,
    group_attrs: dict[str, dict[str, Any]] | None = None,
    config_sha256: str = "",
    inputs: dict[str, str] | None = None,
    compression: str | None = None,
    chunks: str = "auto",
) -> Path:
    """Write an artifact atomically.

    Parameters
    ----------
    path : str or Path
        Target file (``.h5``).
    kind : str
        One of :data:`SCHEMA_VERSIONS`.
    datasets : dict
        ``{"fibers/points": array, ...}``: dataset paths (groups created as needed) to arrays.
    units : dict, optional
        ``{"fibers/points": "m"}``. Every dataset gets a ``units`` attribute (docs/outputs.md):
        datasets without an entry, or with ``""``, are dimensionless and get
        :data:`DIMENSIONLESS` (``"1"``: counts, flags, ratios).
    attrs : dict, optional
        Extra root attributes (scalars, strings; dicts and lists are stored as JSON).
    group_attrs : dict, optional
        Attributes of groups or datasets, by path.
    config_sha256 : str
        Hash of the validated config section(s) that produced the artifact.
    inputs : dict, optional
        ``{name: sha256}`` of the input artifacts.
    compression : str, optional
        h5py compression for large arrays (e.g. ``"gzip"``); None stores them raw.
    chunks : {"auto", "rows"}
        The compressed arrays' chunks: h5py's guess, or along the first axis (:func:`chunk_shape`:
        a frame of a time series per chunk).
    """
    units = units or {}
    with artifact_writer(path, kind, attrs=attrs, config_sha256=config_sha256, inputs=inputs) as f:
        for name, arr in datasets.items():
            name = name.strip("/")
            arr = np.asarray(arr)
            kw = {}
            if compression and arr.size > 4096:
                kw = {"compression": compression, "shuffle": True,
                      "chunks": chunk_shape(arr.shape, arr.itemsize) if chunks == "rows" else True}
            ds = f.create_dataset(name, data=arr, **kw)
            ds.attrs["units"] = units.get(name) or DIMENSIONLESS
        for name, gattrs in (group_attrs or {}).items():
            obj = f.require_group(name.strip("/")) if name.strip("/") not in f else f[name.strip("/")]
            for k, v in gattrs.items():
                obj.attrs[k] = json.dumps(v) if isinstance(v, (dict, list, tuple)) else v
    return Path(path)


@contextmanager
def artifact_writer(path: str | Path, kind: str, *, attrs: dict[str, Any] | None = None, config_sha256: str = "",
                    inputs: dict[str, str] | None = None) -> Iterator[h5py.File]:
    """An artifact written piece by piece (a volume larger than memory, slab by slab): yields the
    open HDF5 file with the root attributes of :func:`write_artifact` set; the caller creates the
    datasets (each with its ``units`` attribute) and may add attributes. Atomic like
    :func:`write_artifact`: the file appears under ``path`` only when the block succeeds."""
    if kind not in SCHEMA_VERSIONS:
        raise ValueError(f"unknown artifact kind {kind!r}")
    root = {
        "kind": kind,
        "schema_version": SCHEMA_VERSIONS[kind],
        "fiberpipe_version": __version__,
        "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "config_sha256": config_sha256,
        "inputs": json.dumps(inputs or {}, sort_keys=True),
    }
    for k, v in (attrs or {}).items():
        root[k] = json.dumps(v) if isinstance(v, (dict, list, tuple)) else v
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as f:
            for k, v in root.items():
                f.attrs[k] = v
            yield f


def _decode(v):
    if isinstance(v, bytes):
        return v.decode()
    if isinstance(v, np.generic):
        return v.item()
    return v


def open_checked(path: str | Path, kind: str | tuple[str, ...]) -> h5py.File:
    """Open an artifact read-only after checking it exists, is HDF5, and has the right kind/version."""
    path = Path(path)
    kinds = (kind,) if isinstance(kind, str) else tuple(kind)
    if not path.exists():
        raise ArtifactError("file not found", where=str(path))
    try:
        f = h5py.File(path, "r")
    except OSError:
        raise ArtifactError("is not a readable HDF5 artifact (damaged or another format)", where=str(path)) from None
    try:
        got = _decode(f.attrs.get("kind"))
        if got is None:
            raise ArtifactError("is HDF5 but not a fiberpipe artifact (no 'kind' attribute)", where=str(path))
        if got not in kinds:
            raise ArtifactError(f"is a {got} artifact, but a {' or '.join(kinds)} artifact is needed", where=str(path))
        version = _decode(f.attrs.get("schema_version"))
        known = SCHEMA_VERSIONS.get(got)
        if not isinstance(version, int) or version != known:
            raise ArtifactError(
                f"has {got} schema version {version}, this fiberpipe {__version__} reads version {known}; "
                "re-run the stage that made it",
                where=str(path),
            )
    except Exception:
        f.close()
        raise
    return f


def read_artifact(path: str | Path, kind: str | tuple[str, ...], *, names: tuple[str, ...] | None = None) -> Artifact:
    """Read an artifact (all datasets, or only ``names``) after checking its kind and version."""
    path = Path(path)
    with open_checked(path, kind) as f:
        attrs = {k: _decode(v) for k, v in f.attrs.items()}
        art = Artifact(path=path, attrs=attrs)

        def visit(name, obj):
            if isinstance(obj, h5py.Dataset):
                if names is None or name in names:
                    art.data[name] = obj[()]
                    art.units[name] = _decode(obj.attrs.get("units", ""))
            if obj.attrs:
                art.group_attrs[name] = {k: _decode(v) for k, v in obj.attrs.items() if k != "units"}

        try:
            f.visititems(visit)
        except OSError:
            raise ArtifactError("is damaged (a dataset cannot be read)", where=str(path)) from None
    if names is not None:
        missing = [n for n in names if n not in art.data]
        if missing:
            raise ArtifactError(f"has no dataset /{missing[0]}", where=str(path))
    return art


# ----------------------------------------------------------------------------------------------
# Typed helpers for the artifacts whose layout is fixed (docs/outputs.md).


def write_fibers(path, polylines, **kw) -> Path:
    """Write a ``fibers`` artifact with the fixed layout /fibers/points, /fibers/offsets, /fibers/radius."""
    return write_artifact(
        path,
        "fibers",
        {
            "fibers/points": polylines.points_m,
            "fibers/offsets": polylines.offsets,
            "fibers/radius": polylines.radius_m,
        },
        units={"fibers/points": "m", "fibers/offsets": INDEX, "fibers/radius": "m"},
        **kw,
    )


def read_json_mapping(path) -> dict:
    """A JSON file holding one mapping (a run's ``summary.json``, ``fiberpipe.lock.json``, post's
    ``summary.json``): {} when it does not exist; an ArtifactError naming it when it does not parse
    or holds something else."""
    path = Path(path)
    if not path.exists():
        return {}
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ArtifactError(f"is not readable JSON ({exc.__class__.__name__})", where=str(path)) from None
    if not isinstance(data, dict):
        raise ArtifactError("is not a JSON mapping", where=str(path))
    return data


def read_fibers(path):
    """Read a ``fibers`` artifact into :class:`~fiberpipe.polylines.Polylines`."""
    from fiberpipe.polylines import Polylines

    art = read_artifact(path, "fibers")
    points = np.asarray(art["fibers/points"])
    if points.ndim != 2 or points.shape[1] != 3:
        raise ArtifactError(f"fibers/points must be an (N, 3) array of positions, got shape {points.shape}",
                            where=str(path))
    try:
        lines = Polylines(points, art["fibers/offsets"], art["fibers/radius"])
    except ValueError as exc:
        raise ArtifactError(f"inconsistent fibers layout: {exc}", where=str(path)) from None
    bad = ~np.isfinite(lines.points_m).all(axis=1)
    if bad.any():
        fiber = int(np.searchsorted(lines.offsets, np.flatnonzero(bad)[0], side="right") - 1)
        raise ArtifactError(f"fiber {fiber} has non-finite coordinates", where=str(path))
    return lines


def write_mesh(path, mesh, *, material: dict | None = None, **kw) -> Path:
    """Write a ``mesh`` artifact: nodes, per-fiber node offsets, connectivity, radius."""
    attrs = dict(kw.pop("attrs", {}) or {})
    if material:
        attrs["material"] = material
    return write_artifact(
        path,
        "mesh",
        {
            "mesh/nodes": mesh.nodes_m,
            "mesh/node_offsets": mesh.node_offsets,
            "mesh/elements": mesh.elements(),
            "mesh/element_fiber": mesh.element_fiber(),
            "mesh/radius": mesh.radius_m,
        },
        units={
            "mesh/nodes": "m",
            "mesh/node_offsets": INDEX,
            "mesh/elements": INDEX,
            "mesh/element_fiber": INDEX,
            "mesh/radius": "m",
        },
        attrs=attrs,
        **kw,
    )


def read_mesh(path):
    """Read a ``mesh`` artifact into :class:`~fiberpipe.model.mesh.Mesh`."""
    from fiberpipe.model.mesh import Mesh

    art = read_artifact(path, "mesh")
    try:
        return Mesh(art["mesh/nodes"], art["mesh/node_offsets"], art["mesh/radius"])
    except ValueError as exc:
        raise ArtifactError(f"inconsistent mesh layout: {exc}", where=str(path)) from None


def write_volume(path, kind: str, volume: np.ndarray, voxel_size_m, *, name: str | None = None, **kw) -> Path:
    """Write a ``volume``, ``mask`` or ``skeleton`` artifact (gzip-compressed, voxel size attribute).

    Units come from :data:`VOLUME_UNITS` (``mask``/``skeleton`` "1", ``radius_vox`` "voxel"),
    overridden by ``units=``.
    """
    name = name or kind
    attrs = dict(kw.pop("attrs", {}) or {})
    attrs["voxel_size_m"] = list(np.broadcast_to(np.asarray(voxel_size_m, float), (3,)))
    datasets = {name: volume}
    datasets.update(kw.pop("extra", {}) or {})
    units = {k: VOLUME_UNITS[k.strip("/")] for k in datasets if k.strip("/") in VOLUME_UNITS}
    units.update(kw.pop("units", {}) or {})
    return write_artifact(path, kind, datasets, units=units, attrs=attrs, compression="gzip", **kw)
