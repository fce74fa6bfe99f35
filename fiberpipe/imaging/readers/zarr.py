"""Zarr (v2 and v3 stores, OME-Zarr images), read with zarr. A group gives its OME-NGFF
``multiscales`` full-resolution array, or its only array of 3 or more dimensions; the voxel size
comes from the OME-NGFF scale and axis units, or from ``voxel_size_m`` / ``voxel_size`` (+
``units``) / ``element_size_um`` attributes."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import InputError
from .._util import voxel_size_zyx
from . import register
from ._common import attrs_voxel_size, need, read_whole, unit_to_m, why


def is_zarr_folder(p: Path) -> bool:
    return p.suffix.lower() == ".zarr" or any((p / m).exists() for m in ("zarr.json", ".zarray", ".zgroup"))


def _ome(group) -> tuple[str, np.ndarray | None] | None:
    """(path of the full-resolution array, voxel size or None) from OME-NGFF ``multiscales``."""
    attrs = dict(group.attrs)
    ms = attrs.get("multiscales") or attrs.get("ome", {}).get("multiscales")
    if not ms:
        return None
    m = ms[0]
    ds = m["datasets"][0]
    scale = None
    for t in ds.get("coordinateTransformations", []):
        if t.get("type") == "scale":
            scale = [float(x) for x in t["scale"]]
    axes = m.get("axes", [])
    vs = None
    if scale is not None and len(scale) >= 3:
        units = [a.get("unit") if isinstance(a, dict) else None for a in axes][-3:] if axes else [None] * 3
        f = [unit_to_m(u) for u in units]
        if all(x is not None for x in f):
            vs = voxel_size_zyx(np.array(scale[-3:]) * np.array(f))
    return ds["path"], vs


def _arrays(group, prefix=""):
    out = []
    for name, a in group.arrays():
        out.append((prefix + name, a))
    for name, g in group.groups():
        out += _arrays(g, prefix + name + "/")
    return out


def _locate(path: Path, dataset: str | None):
    """(array, its name in the store, voxel size or None) without reading the data."""
    where = str(path)
    zarr = need("zarr", "Zarr", where)
    try:
        node = zarr.open(str(path), mode="r")
    except Exception as exc:  # noqa: BLE001
        raise InputError(f"cannot open Zarr store ({why(exc)})", where=where) from None
    vs = None
    name = ""
    if isinstance(node, zarr.Array):
        arr = node
    else:
        ome = _ome(node) if dataset is None else None
        if ome is not None:
            name, vs = ome
        elif dataset is not None:
            name = dataset
        else:
            found = [(n, a) for n, a in _arrays(node) if a.ndim >= 3]
            if len(found) != 1:
                what = "no 3D array" if not found else f"several 3D arrays {[n for n, _ in found]}"
                raise InputError(f"{what}; give the dataset name", where=where)
            name = found[0][0]
        try:
            arr = node[name]
        except KeyError:
            raise InputError(f"no array {name!r} in the Zarr store", where=where) from None
        if vs is None:
            vs = attrs_voxel_size(dict(node.attrs))
    if vs is None:
        try:
            vs = attrs_voxel_size(dict(arr.attrs))
        except (ValueError, TypeError):
            vs = None
    return arr, name, vs


def locate(path: Path, *, dataset: str | None = None):
    """(array name or None for a plain array, voxel size or None, shape, dtype) without reading
    the data: the input of the chunked stages."""
    arr, name, vs = _locate(path, dataset)
    return name or None, vs, tuple(arr.shape), np.dtype(arr.dtype)


def read(path: Path, *, dataset: str | None = None, **_):
    arr, name, vs = _locate(path, dataset)
    vol = read_whole(arr, f"Zarr array {name or '/'!r}", str(path))
    return np.asarray(vol), vs, f"zarr:{path}" + (f":{name}" if name else "")


register("zarr", (".zarr",), read, claims_folder=is_zarr_folder)
