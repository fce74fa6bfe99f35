"""HDF5 and NeXus (HDF5 with NXentry/NXdata groups): the named dataset, the NeXus default
signal, or the file's only dataset with 3 or more dimensions."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import InputError
from .._util import voxel_size_zyx
from . import register
from ._common import attrs_voxel_size, read_whole, unit_to_m, why

SUFFIXES = (".h5", ".hdf5", ".hdf", ".he5", ".nxs", ".nx5")

#: Kinds of fiberpipe artifacts that hold an image (read as a volume); the others (fibers, mesh,
#: simulation, ...) are refused as a volume input instead of reading one of their arrays.
_IMAGE_KINDS = ("volume", "mask")


def _text(v):
    if isinstance(v, bytes):
        return v.decode()
    if isinstance(v, np.ndarray) and v.dtype.kind in "SO" and v.size == 1:
        return _text(v.reshape(-1)[0])
    return v


def _find_3d_datasets(h5):
    import h5py

    found = []

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset) and obj.ndim >= 3:
            found.append(name)

    h5.visititems(visit)
    return found


def _nexus_signal(h5) -> str | None:
    """Path of the NeXus signal to read: the 3D signal the ``default`` chain (root -> NXentry ->
    NXdata) leads to, else the only 3D signal of all NXdata groups, else None."""
    import h5py

    g = h5
    for _ in range(3):  # root -> NXentry -> NXdata, following @default
        d = _text(g.attrs.get("default"))
        if not isinstance(d, str) or d not in g or not isinstance(g[d], h5py.Group):
            break
        g = g[d]
    groups = []

    def visit(name, obj):
        if isinstance(obj, h5py.Group) and _text(obj.attrs.get("NX_class")) == "NXdata":
            groups.append(obj)

    h5.visititems(visit)
    signals = {}
    for grp in groups:
        sig = _text(grp.attrs.get("signal"))
        if isinstance(sig, str) and sig in grp and getattr(grp[sig], "ndim", 0) >= 3:
            signals[grp.name] = grp[sig].name.lstrip("/")
    if g.name in signals:
        return signals[g.name]
    return next(iter(signals.values())) if len(signals) == 1 else None


def _nexus_voxel_size(ds) -> np.ndarray | None:
    """(dz, dy, dx) in m from the NXdata ``axes`` of a signal: the spacing of each of its last three
    axis coordinate arrays, in their ``units``."""
    grp = ds.parent
    axes = grp.attrs.get("axes")
    if axes is None:
        return None
    names = [_text(a) for a in (list(axes) if not isinstance(axes, (str, bytes)) else [axes])]
    if len(names) < 3:
        return None
    out = []
    for n in names[-3:]:
        if not isinstance(n, str) or n not in grp:
            return None
        a = np.asarray(grp[n][()], dtype=np.float64).reshape(-1)
        f = unit_to_m(_text(grp[n].attrs.get("units")))
        if len(a) < 2 or f is None:
            return None
        step = np.diff(a)
        if not np.allclose(step, step[0], rtol=1e-4):
            return None
        out.append(abs(float(step[0])) * f)
    return voxel_size_zyx(out)


def _voxel_size(ds) -> np.ndarray | None:
    for obj in (ds, ds.file):
        vs = attrs_voxel_size(obj.attrs)
        if vs is not None:
            return vs
    return _nexus_voxel_size(ds)


def _read_data(ds, dataset: str, where: str) -> np.ndarray:
    return read_whole(ds, f"dataset {dataset!r}", where)


def _locate(h5, dataset: str | None, where: str):
    """The dataset to read in an open file (named, the NeXus default signal, or the only 3D one)
    and its voxel size (or None)."""
    kind = _text(h5.attrs.get("kind"))
    if dataset is None and isinstance(kind, str) and kind not in _IMAGE_KINDS:
        raise InputError(
            f"is a fiberpipe {kind} artifact, not a volume; input.volume takes a CT volume (TIFF, folder "
            f"of slices, .npy, HDF5 image, raw)" + (", and input.fibers a fibers artifact" if kind == "fibers" else ""),
            where=where)
    if dataset is None:
        names = _find_3d_datasets(h5)
        if len(names) != 1:
            sig = _nexus_signal(h5)
            if sig is not None:
                names = [sig]
        if len(names) != 1:
            what = "no 3D dataset" if not names else f"several 3D datasets {names}"
            raise InputError(f"{what}; give the dataset name", where=where)
        dataset = names[0]
    if dataset not in h5:
        raise InputError(f"no dataset {dataset!r}", where=where)
    try:
        vs = _voxel_size(h5[dataset])
    except (ValueError, TypeError):  # an unreadable attribute is no voxel size (give voxel_size)
        vs = None
    return dataset, vs


def _open(path: Path):
    import h5py

    try:
        return h5py.File(path, "r")
    except OSError as exc:
        raise InputError(f"cannot open HDF5 file ({why(exc)}); not HDF5 or truncated", where=str(path)) from None


def locate(path: Path, *, dataset: str | None = None):
    """(dataset name, voxel size or None, shape, dtype) without reading the data: the input of
    the chunked stages."""
    with _open(path) as h5:
        name, vs = _locate(h5, dataset, str(path))
        ds = h5[name]
        return name, vs, tuple(ds.shape), ds.dtype


def read(path: Path, *, dataset: str | None = None, **_):
    where = str(path)
    with _open(path) as h5:
        dataset, vs = _locate(h5, dataset, where)
        vol = _read_data(h5[dataset], dataset, where)
    return vol, vs, f"hdf5:{path}:{dataset}"


register("hdf5", SUFFIXES, read)
