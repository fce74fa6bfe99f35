"""Synthetic CT of a dense composite: fibers packed at v_f 0.6, touching on all sides, with a
cross ply (a tow whose fibers lie in the slice plane).

Carbon and glass composites are scanned at 5-7 voxels per fiber diameter, so their fibers are thin
(r = 2.5-3.5 voxels), the contrast is low (CNR 2-3) and neighbours touch everywhere. In a woven
or cross-ply part a second tow runs across the first, its fibers lying in the slices. The phantom
has both: a main ply of fibers along z (axis 0) over ``y < ply_split`` and a cross ply of fibers
along x (axis 2) over the rest of the y range, each packed at the target fiber volume fraction.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial import cKDTree

from ..errors import InputError
from ..polylines import Polylines
from .phantom import STUDY_FIBER_DIAMETER_M, _render_vox, _to_dtype
from ._util import voxel_to_xyz_m

#: The dense-composite family (:func:`make_dense_family_phantom`): ranges drawn per seed.
DENSE_FAMILY = {"shape": (100, 100, 100), "radius_vox": (2.5, 5.0), "contrast_to_noise": (2.0, 5.0),
                "fiber_volume_fraction": (0.45, 0.6), "cross_ply_fraction": 0.3, "misalignment_deg": (0.0, 3.0),
                "waviness_vox": (0.0, 1.5), "ring_contrast": (0.1, 0.3), "cupping": (0.05, 0.2)}


class ScanArtefacts(NamedTuple):
    """What a lab scanner adds to the dense phantom (fractions of the fiber-matrix contrast)."""

    ring_contrast: float = 0.0   # concentric rings about the rotation axis (z), each 1 voxel wide
    n_rings: int = 4
    cupping: float = 0.0         # beam hardening: the centre of each slice darker by this fraction


def _add_artefacts(vol: np.ndarray, artefacts: ScanArtefacts, rng) -> None:
    """Rings (bad detector pixels: a circle about the rotation axis in every slice) and cupping
    (beam hardening: ``1 - c (1 - (rho / rho_max)^2)`` times the grey, darkest at the axis), in place
    on the float volume (background 0, fiber 1) before its noise."""
    if not (artefacts.ring_contrast or artefacts.cupping):
        return
    _, ny, nx = vol.shape
    yy, xx = np.indices((ny, nx), dtype=np.float32)
    rho = np.hypot(yy - (ny - 1) / 2, xx - (nx - 1) / 2)
    add = np.zeros((ny, nx), np.float32)
    for radius in rng.uniform(0.1, 0.7, artefacts.n_rings) * min(ny, nx):
        add += np.float32(artefacts.ring_contrast * rng.choice([-1.0, 1.0])) * np.exp(-0.5 * (rho - radius) ** 2 / 0.25)
    gain = 1.0 - artefacts.cupping * (1.0 - (rho / rho.max()) ** 2)
    vol *= gain.astype(np.float32)
    vol += add


def pack_disks(n: int, radius: float, lo, hi, rng, *, init=None, jitter: float = 0.0,
               n_iter: int = 400, tol: float = 0.02) -> np.ndarray:
    """Centres of ``n`` non-overlapping disks of ``radius`` in the box ``lo <= c <= hi`` (2D).

    Overlap removal from random (or given, then jittered) positions: every overlapping pair is
    pushed apart along its centre line by its overlap, repeatedly, with the centres clamped to the
    box, until no pair overlaps by more than ``tol``. Pairs that overlapped end at contact, so at a
    fiber volume fraction of 0.6 most disks touch several neighbours, as in the cross-section of a
    unidirectional composite.
    """
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c = rng.uniform(lo, hi, (n, 2)) if init is None else np.array(init, float)
    if jitter:
        c += rng.normal(0.0, jitter, c.shape)
    np.clip(c, lo, hi, out=c)
    d2 = 2.0 * radius
    for _ in range(n_iter):
        pairs = cKDTree(c).query_pairs(d2 - tol, output_type="ndarray")
        if len(pairs) == 0:
            break
        dv = c[pairs[:, 1]] - c[pairs[:, 0]]
        d = np.linalg.norm(dv, axis=1)
        tiny = d < 1e-9
        dv[tiny] = rng.normal(size=(int(tiny.sum()), 2))
        d[tiny] = np.linalg.norm(dv[tiny], axis=1)
        push = 0.5 * (d2 - d + 1e-3)[:, None] * dv / d[:, None] * 0.6
        np.add.at(c, pairs[:, 0], -push)
        np.add.at(c, pairs[:, 1], push)
        np.clip(c, lo, hi, out=c)
    return c


def _ply_paths(n: int, radius: float, lo, hi, length: int, ext: int, rng, *, n_planes: int = 5,
               jitter: float = 0.6) -> np.ndarray:
    """Paths (length + 2 ext, n, 2) of ``n`` fibers packed in the box ``lo..hi`` of their cross-section:
    packings at ``n_planes`` planes along the fiber axis (each the previous one jittered and
    relaxed), linearly interpolated and smoothed, so the fibers wander slowly and stay in contact."""
    t = np.arange(-ext, length + ext, dtype=float)
    knots = np.linspace(t[0], t[-1], n_planes)
    planes = [pack_disks(n, radius, lo, hi, rng)]
    for _ in range(n_planes - 1):
        planes.append(pack_disks(n, radius, lo, hi, rng, init=planes[-1], jitter=jitter))
    P = np.stack(planes)  # (n_planes, n, 2)
    out = np.empty((len(t), n, 2))
    for i in range(n):
        for a in range(2):
            out[:, i, a] = np.interp(t, knots, P[:, i, a])
    return gaussian_filter1d(out, 0.25 * (knots[1] - knots[0]), axis=0, mode="nearest")


def _n_fibers(vf: float, radius: float, extent) -> int:
    return int(round(vf * float(np.prod(extent)) / (np.pi * radius * radius)))


def make_dense_phantom(*, shape=(100, 100, 100), radius_vox: float = 3.0, fiber_volume_fraction: float = 0.6,
                       cross_ply_fraction: float = 0.3, contrast_to_noise: float = 2.5,
                       blur_sigma_vox: float = 0.8, voxel_size_m: float | None = None, seed: int = 0,
                       dtype="uint16", misalignment_deg: float = 0.0, waviness_vox: float = 0.0,
                       artefacts: ScanArtefacts | None = None):
    """Make a dense-composite volume with ground truth.

    Parameters
    ----------
    shape : (3,) ints
        Volume (z, y, x), voxels. Main-ply fibers run along z through the whole volume; cross-ply
        fibers along x through the whole volume.
    radius_vox : float
    fiber_volume_fraction : float
        Fiber area fraction of each ply's cross-section (including the ply's border margin).
    cross_ply_fraction : float
        Share of the y range taken by the cross ply (0: none, one ply along z).
    contrast_to_noise, blur_sigma_vox, voxel_size_m, seed, dtype
        As :func:`fiberpipe.imaging.phantom.make_phantom`.
    misalignment_deg : float
        The main ply tilted by this angle from z (in a random direction of the slice plane), all its
        fibers together, as a ply laid a few degrees off.
    waviness_vox : float
        In-phase waviness of the main ply: a sine of this amplitude (voxels) and one wavelength over
        the volume's length, in a random direction.
    artefacts : ScanArtefacts, optional
        Rings and beam-hardening cupping (:class:`ScanArtefacts`), added before the noise.

    Returns
    -------
    volume : (Z, Y, X) ndarray of ``dtype``
    truth : Polylines
        True mid-lines (x y z, m; main ply first) and radii; ``truth.meta`` holds ``axis_zyx`` (0 for
        a main-ply fiber, 2 for a cross-ply one), ``n_main``, ``n_cross``, ``contact_fraction``
        (fibers touching at least one neighbour, surface gap < 0.25 voxel, in the middle slice of
        their ply), ``min_surface_gap_vox`` (most negative: the largest overlap anywhere), the
        achieved fiber volume fraction, ``voxel_size_m``, ``radius_vox``, ``contrast_to_noise``,
        ``misalignment_deg``, ``waviness_vox``.
    """
    nz, ny, nx = (int(s) for s in shape)
    r = float(radius_vox)
    if not (0 < fiber_volume_fraction < 0.8):
        raise InputError(f"phantom: fiber_volume_fraction must be in (0, 0.8), got {fiber_volume_fraction!r}")
    vs = float(STUDY_FIBER_DIAMETER_M / (2 * r) if voxel_size_m is None else voxel_size_m)
    rng = np.random.default_rng(seed)
    ext = int(np.ceil(r + 2))
    split = int(round(ny * (1.0 - cross_ply_fraction)))
    m = r + 1.0  # centres keep a one-voxel margin to the volume border (make_phantom's rule)
    # main ply: centres (y, x) in [m, split - r] x [m, nx - 1 - m], less the ply's drift
    z = np.arange(-ext, nz + ext, dtype=float)
    drift = _ply_drift(z, nz, misalignment_deg, waviness_vox, np.random.default_rng(seed + 2))
    reach = np.abs(drift).max(axis=0)
    lo, hi = np.array([m, m]) + reach, np.array([split - r - 0.5, nx - 1 - m]) - reach
    n_main = _n_fibers(fiber_volume_fraction, r, (hi - lo + 2 * r))
    paths = _ply_paths(n_main, r, lo, hi, nz, ext, rng) + drift[:, None, :]
    lines = [np.column_stack([z, paths[:, i, 0], paths[:, i, 1]]) for i in range(n_main)]
    gaps, n_cross = [paths], 0
    if cross_ply_fraction > 0:
        # cross ply: fibers along x, centres (z, y) in [m, nz - 1 - m] x [split + r + 0.5, ny - 1 - m]
        lo, hi = np.array([m, split + r + 0.5]), np.array([nz - 1 - m, ny - 1 - m])
        if np.any(hi <= lo):
            raise InputError(f"phantom: the cross ply ({ny - split} voxels of y) is too thin for fibers of radius {r:g}")
        n_cross = _n_fibers(fiber_volume_fraction, r, (hi - lo + 2 * r))
        cp = _ply_paths(n_cross, r, lo, hi, nx, ext, rng)
        x = np.arange(-ext, nx + ext, dtype=float)
        lines += [np.column_stack([cp[:, i, 0], cp[:, i, 1], x]) for i in range(n_cross)]
        gaps.append(cp)
    axes = [0] * n_main + [2] * n_cross
    min_gap, touching = _contacts(gaps, r)
    vol = _render_vox(lines, [r] * len(lines), (nz, ny, nx), blur_sigma_vox=blur_sigma_vox, contrast_to_noise=0.0,
                      seed=seed + 1, background=0.0, foreground=1.0, dtype="float32")
    _add_artefacts(vol, artefacts or ScanArtefacts(), np.random.default_rng(seed + 3))
    noise, sigma = np.random.default_rng(seed + 1), 1.0 / float(contrast_to_noise)
    for k in range(nz):  # slice by slice: no second full-size array (make_phantom's noise)
        vol[k] += sigma * noise.standard_normal((ny, nx), dtype=np.float32)
    inside = [voxel_to_xyz_m(ln[(ln[:, a] >= 0) & (ln[:, a] <= shape[a] - 1)], vs) for ln, a in zip(lines, axes)]
    truth = Polylines.from_list(inside, r * vs)
    area = np.pi * r * r
    truth.meta.update(axis_zyx=np.array(axes, dtype=np.int64), n_main=n_main, n_cross=n_cross,
                      contact_fraction=touching / max(1, len(lines)), min_surface_gap_vox=min_gap,
                      fiber_volume_fraction=float((n_main * area * nz + n_cross * area * nx) / (nz * ny * nx)),
                      voxel_size_m=vs, radius_vox=r, seed=seed, contrast_to_noise=float(contrast_to_noise),
                      misalignment_deg=float(misalignment_deg), waviness_vox=float(waviness_vox))
    return _to_dtype(vol, dtype, 0.0, 1.0), truth


def _ply_drift(z: np.ndarray, length: int, misalignment_deg: float, waviness_vox: float, rng) -> np.ndarray:
    """The in-plane offset (len(z), 2) of a whole ply along its axis: a tilt of ``misalignment_deg``
    and a sine of ``waviness_vox`` over one wavelength of ``length``, each in a random direction."""
    tilt_dir = rng.uniform(0, 2 * np.pi)
    wave_dir = rng.uniform(0, 2 * np.pi)
    t = z - 0.5 * (length - 1)
    tilt = np.tan(np.radians(misalignment_deg)) * t
    wave = waviness_vox * np.sin(2 * np.pi * z / length + rng.uniform(0, 2 * np.pi))
    return (np.outer(tilt, [np.cos(tilt_dir), np.sin(tilt_dir)])
            + np.outer(wave, [np.cos(wave_dir), np.sin(wave_dir)]))


def _contacts(plies: list, r: float) -> tuple[float, int]:
    """The smallest surface gap (voxels; negative: an overlap) of every other cross-section of the
    plies' paths, and the number of fibers touching a neighbour (gap < 0.25) in each ply's middle."""
    min_gap, touching = np.inf, 0
    for P in plies:
        for k in range(0, P.shape[0], 2):
            dd, _ = cKDTree(P[k]).query(P[k], k=2)
            min_gap = min(min_gap, float(dd[:, 1].min()) - 2 * r)
        dd, _ = cKDTree(P[P.shape[0] // 2]).query(P[P.shape[0] // 2], k=2)
        touching += int(np.sum(dd[:, 1] - 2 * r < 0.25))
    return min_gap, touching


def make_dense_family_phantom(seed: int, **overrides):
    """A phantom of the dense-composite family (:data:`DENSE_FAMILY`): per seed, r drawn from
    2.5-5 voxels, CNR 2-5, v_f 0.45-0.6, the main ply misaligned by 0-3 degrees and wavy by 0-1.5
    voxels, rings of 0.1-0.3 and cupping of 0.05-0.2 of the contrast; 100^3 voxels, a cross ply over
    30 % of the y range. ``overrides`` go to :func:`make_dense_phantom`."""
    f = DENSE_FAMILY
    rng = np.random.default_rng(20_000 + seed)
    kw = dict(shape=f["shape"], radius_vox=float(rng.uniform(*f["radius_vox"])),
              contrast_to_noise=float(rng.uniform(*f["contrast_to_noise"])),
              fiber_volume_fraction=float(rng.uniform(*f["fiber_volume_fraction"])),
              cross_ply_fraction=f["cross_ply_fraction"], misalignment_deg=float(rng.uniform(*f["misalignment_deg"])),
              waviness_vox=float(rng.uniform(*f["waviness_vox"])),
              artefacts=ScanArtefacts(ring_contrast=float(rng.uniform(*f["ring_contrast"])),
                                      cupping=float(rng.uniform(*f["cupping"]))), seed=seed)
    kw.update(overrides)
    return make_dense_phantom(**kw)
