"""Synthetic CT volumes of curved, quasi-parallel, touching fibers with exact mid-lines.

The phantom is the accuracy reference for the tracers (no public CT of this geometry has ground
truth). It reproduces the image effects that make tracing hard: fibers touching along their whole
length (so they merge in any binary mask), partial-volume edges, a blurring point-spread function
and Gaussian noise at a chosen contrast-to-noise ratio.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.ndimage import gaussian_filter

from ..errors import InputError
from ..polylines import Polylines
from ._kernels import render_segments_max
from ._util import voxel_size_zyx, xyz_m_to_voxel, voxel_to_xyz_m

#: Fiber diameter of the study (polyester, 0.5 mm): the default voxel size makes it so.
STUDY_FIBER_DIAMETER_M = 0.5e-3


def _to_dtype(occ_or_grey: np.ndarray, dtype, background: float, foreground: float) -> np.ndarray:
    """Convert a float32 grey volume to the requested dtype (in place for float32)."""
    dtype = np.dtype(dtype)
    if dtype == np.float32:
        return occ_or_grey
    if dtype.kind != "u":
        return occ_or_grey.astype(dtype)
    # Strategy: map background to 1/4 and foreground to 3/4 of the integer range, so noise of a
    # CNR >= 2 almost never clips and the grey values look like a reconstructed CT.
    top = np.iinfo(dtype).max
    lo, hi = 0.25 * top, 0.75 * top
    scale = (hi - lo) / (foreground - background)
    v = occ_or_grey
    v -= background
    v *= scale
    v += lo
    np.clip(v, 0, top, out=v)
    np.rint(v, out=v)
    return v.astype(dtype)


def _render_vox(lines_zyx, radii_vox, shape, *, blur_sigma_vox, contrast_to_noise, seed,
                background, foreground, dtype) -> np.ndarray:
    """Render centre-lines given in voxel coordinates (z y x) into a grey volume."""
    shape = tuple(int(s) for s in shape)
    occ = np.zeros(shape, dtype=np.float32)
    starts, ends, rad = [], [], []
    for line, r in zip(lines_zyx, radii_vox):
        line = np.asarray(line, dtype=np.float64)
        if len(line) == 1:
            line = np.repeat(line, 2, axis=0)
        starts.append(line[:-1])
        ends.append(line[1:])
        rad.append(np.full(len(line) - 1, float(r)))
    if starts:
        render_segments_max(occ, np.concatenate(starts), np.concatenate(ends), np.concatenate(rad),
                            np.asarray(shape, dtype=np.int64))
    # occupancy -> grey level, in place (no second full-size array)
    occ *= foreground - background
    occ += background
    if blur_sigma_vox and blur_sigma_vox > 0:
        gaussian_filter(occ, blur_sigma_vox, output=occ, mode="nearest")
    if contrast_to_noise:
        rng = np.random.default_rng(seed)
        sigma = abs(foreground - background) / float(contrast_to_noise)
        # slice by slice to keep the temporary noise array small
        for k in range(shape[0]):
            occ[k] += sigma * rng.standard_normal(shape[1:], dtype=np.float32)
    return _to_dtype(occ, dtype, background, foreground)


def render_polylines(polylines: Polylines, shape, voxel_size_m, *, blur_sigma_vox: float = 1.0,
                     contrast_to_noise: float | None = 5.0, seed: int = 0, background: float = 0.0,
                     foreground: float = 1.0, dtype="float32") -> np.ndarray:
    """Render any set of fibers (tubes around polylines) into a CT-like volume.

    Parameters
    ----------
    polylines : Polylines
        Mid-lines (x y z, m) and radii (m); e.g. ground truth or a simulation frame.
    shape : (3,) ints
        Volume shape (z, y, x), voxels.
    voxel_size_m : float or (dz, dy, dx)
        Voxel size, m. Radii are converted with the in-plane size ``dx``.
    blur_sigma_vox : float
        Standard deviation of the Gaussian point-spread function, voxels (0: none).
    contrast_to_noise : float or None
        (foreground - background) / noise standard deviation; None or 0: no noise.
    seed : int
        Noise seed (deterministic output).
    background, foreground : float
        Grey levels of empty space and of fiber material before blur and noise.
    dtype : numpy dtype
        float32 (returned as is) or an unsigned integer type (background at 1/4, foreground at 3/4 of
        the range).

    Returns
    -------
    volume : (Z, Y, X) ndarray of ``dtype``
    """
    v = voxel_size_zyx(voxel_size_m)
    lines = [xyz_m_to_voxel(f, v) for f in polylines]
    radii = np.asarray(polylines.radius_m) / v[2]
    return _render_vox(lines, radii, shape, blur_sigma_vox=blur_sigma_vox,
                       contrast_to_noise=contrast_to_noise, seed=seed, background=background,
                       foreground=foreground, dtype=dtype)


def min_cross_section_vox(radius_vox: float) -> int:
    """Smallest y and x size (voxels) a phantom of fibers of ``radius_vox`` needs: the fiber
    diameter plus the one-voxel margin (and the rendering's one-voxel ramp) each side, the room
    :func:`make_phantom` places fiber centres in (``r + 1 .. size - 2 - r``)."""
    return int(np.ceil(2.0 * float(radius_vox) + 3.0))


def check_phantom_fits(shape, radius_vox: float, n_fibers: int = 1) -> None:
    """Raise :class:`InputError` if fibers of ``radius_vox`` cannot fit the phantom's ``shape``."""
    try:
        dims = [int(v) for v in shape]
    except (TypeError, ValueError):
        dims = []
    if len(dims) != 3 or min(dims) < 1:
        raise InputError(f"phantom: shape must be 3 positive sizes (z y x) in voxels, got {shape!r}")
    r = float(radius_vox)
    if not (r > 0 and np.isfinite(r)):
        raise InputError(f"phantom: radius_vox must be positive, got {radius_vox!r}")
    if int(n_fibers) < 1:
        raise InputError(f"phantom: n_fibers must be at least 1, got {n_fibers!r}")
    need = min_cross_section_vox(r)
    _, ny, nx = dims
    if min(ny, nx) < need:
        raise InputError(
            f"phantom: fibers of radius {r:g} voxels do not fit the {ny}x{nx} (y x) cross-section of shape "
            f"{tuple(dims)}: a fiber needs at least {need} voxels along y and x (its diameter plus a margin); "
            f"enlarge the shape or lower radius_vox (at most {(min(ny, nx) - 3) / 2:g} for this shape)")


class PhantomOptions(NamedTuple):
    """The paths and the rendering of :func:`make_phantom` (its keyword options)."""

    touching_fraction: float = 1 / 3
    waviness_vox: float = 2.0
    wavelength_vox: float | None = None
    max_tilt: float = 0.04
    min_gap_vox: float = 0.5
    contrast_to_noise: float = 5.0
    blur_sigma_vox: float = 1.0
    background: float = 0.0
    foreground: float = 1.0
    dtype: str = "float32"
    max_attempts: int = 20000


def make_phantom(*, n_fibers: int = 40, shape=(200, 120, 120), radius_vox: float = 5.0,
                 voxel_size_m: float | None = None, seed: int = 0, **options):
    """Make a synthetic volume of curved quasi-parallel fibers along z, with ground truth.

    Parameters (``options``: the fields of :class:`PhantomOptions`)
    ----------
    n_fibers : int
        Number of fibers.
    shape : (3,) ints
        Volume shape (z, y, x), voxels; fibers run along z through the whole volume.
    radius_vox : float
        Fiber radius, voxels.
    voxel_size_m : float, optional
        Isotropic voxel size, m. Default: the study's 0.5 mm fiber diameter spans ``2 radius_vox``.
    touching_fraction : float
        Fraction of fibers placed in pairs whose centre distance is exactly ``2 radius`` and that
        share the same path, so they touch along their whole length.
    waviness_vox : float
        Amplitude scale of the sinusoidal waviness of each fiber (x and y), voxels.
    wavelength_vox : float, optional
        Wavelength scale of the waviness, voxels (default: max(shape[0], 100)).
    max_tilt : float
        Largest slope (dx/dz, dy/dz) of a fiber's mean direction; 0.04 is about 2.3 degrees.
    min_gap_vox : float
        Smallest surface gap between fibers that are not designed to touch, voxels.
    contrast_to_noise : float
        (foreground - background) / noise standard deviation (0: no noise).
    blur_sigma_vox : float
        Gaussian point-spread function, voxels.
    seed : int
        Random seed; the phantom is a deterministic function of all arguments.
    background, foreground, dtype
        Grey levels and output type, see :func:`render_polylines`.
    max_attempts : int
        Random placements tried per fiber before giving up.

    Returns
    -------
    volume : (Z, Y, X) ndarray of ``dtype``
    truth : Polylines
        True mid-lines (x y z, m, one point per slice over the volume) and radii (m);
        ``truth.meta`` holds ``touching`` (bool per fiber) and ``voxel_size_m``.

    Raises
    ------
    InputError
        If a fiber does not fit the cross-section at all (:func:`check_phantom_fits`), or the
        fibers cannot be placed without overlap (too many for the cross-section).
    """
    # Strategy: random sequential addition of "units" (a single fiber, or a touching pair sharing
    # one path) in the cross-section. Each unit's path is base + tilt * z + two sinusoids; a unit is
    # accepted only if, in every slice, it keeps 2 r + min_gap from every fiber placed before. Pairs
    # go first (they need the most room). Rendering is exact distance-to-polyline with a one-voxel
    # partial-volume ramp, then PSF blur, then noise.
    unknown = sorted(set(options) - set(PhantomOptions._fields))
    if unknown:
        raise TypeError(f"make_phantom() got an unexpected keyword argument {unknown[0]!r}")
    o = PhantomOptions(**options)
    nz, ny, nx = (int(s) for s in shape)
    r = float(radius_vox)
    check_phantom_fits(shape, r, n_fibers)
    if voxel_size_m is None:
        voxel_size_m = STUDY_FIBER_DIAMETER_M / (2 * r)
    vs = float(np.asarray(voxel_size_m).reshape(-1)[0])
    ext = int(np.ceil(r + 2))
    z = np.arange(-ext, nz + ext, dtype=np.float64)
    n_pairs = min(int(round(n_fibers * o.touching_fraction / 2.0)), n_fibers // 2)
    units = [2] * n_pairs + [1] * (n_fibers - 2 * n_pairs)
    placed, touching = _place_units(units, z, (nz, ny, nx), r, o, np.random.default_rng(seed))
    inside = (z >= 0) & (z <= nz - 1)
    lines_vox = [np.column_stack([z, p[:, 0], p[:, 1]]) for p in placed]
    vol = _render_vox(lines_vox, [r] * len(lines_vox), (nz, ny, nx), blur_sigma_vox=o.blur_sigma_vox,
                      contrast_to_noise=o.contrast_to_noise, seed=seed + 1, background=o.background,
                      foreground=o.foreground, dtype=o.dtype)
    truth = Polylines.from_list([voxel_to_xyz_m(l[inside], vs) for l in lines_vox], r * vs)
    truth.meta.update(touching=np.array(touching, dtype=bool), voxel_size_m=vs,
                      radius_vox=r, seed=seed)
    return vol, truth


def _place_units(units: list, z: np.ndarray, shape, r: float, o: PhantomOptions, rng) -> tuple[list, list]:
    """Random sequential addition of the units (1: a fiber, 2: a touching pair) in the
    cross-section: the accepted paths ((len(z), 2) y, x each) and whether each fiber touches."""
    nz, ny, nx = shape
    lam0 = float(o.wavelength_vox or max(nz, 100))
    zc = 0.5 * (nz - 1)
    lo_y, hi_y = r + 1.0, ny - 2.0 - r
    lo_x, hi_x = r + 1.0, nx - 2.0 - r
    inside = (z >= 0) & (z <= nz - 1)
    placed: list[np.ndarray] = []
    touching: list[bool] = []
    for size in units:
        for _attempt in range(o.max_attempts):
            tilt = rng.uniform(-o.max_tilt, o.max_tilt, 2)
            amp = o.waviness_vox * rng.uniform(0.3, 1.0, 2)
            lam = lam0 * rng.uniform(0.7, 1.5, 2)
            phase = rng.uniform(0, 2 * np.pi, 2)
            base = np.array([rng.uniform(lo_y, hi_y), rng.uniform(lo_x, hi_x)])
            path = base + np.outer(z - zc, tilt) + amp * np.sin(2 * np.pi * z[:, None] / lam + phase)
            cand = [path]
            if size == 2:
                a = rng.uniform(0, np.pi)
                cand.append(path + 2 * r * np.array([np.sin(a), np.cos(a)]))
            ok = all(c[inside][:, 0].min() >= lo_y and c[inside][:, 0].max() <= hi_y and c[inside][:, 1].min() >= lo_x
                     and c[inside][:, 1].max() <= hi_x for c in cand)
            if ok and placed:
                P = np.stack(placed)  # (F, Z, 2)
                ok = all(np.sqrt(((P - c[None]) ** 2).sum(-1)).min() >= 2 * r + o.min_gap_vox for c in cand)
            if ok:
                placed.extend(cand)
                touching.extend([size == 2] * size)
                break
        else:
            raise InputError(
                f"phantom: cannot place {sum(units)} fibers of radius {r} vox in a {ny}x{nx} "
                f"cross-section (placed {len(placed)}); use fewer fibers, a smaller radius or a larger volume")
    return placed, touching


def make_short_fiber_phantom(*, shape=(100, 180, 270), n_fibers: int = 150, radius_vox: float = 2.7,
                             length_vox=(25.0, 80.0), orientation: str = "planar", min_gap_vox: float = 0.5,
                             voxel_size_m: float = 10e-6, contrast_to_noise: float = 4.0,
                             blur_sigma_vox: float = 0.8, seed: int = 0, dtype="uint16",
                             max_attempts: int = 200):
    """Make a synthetic CT of a short-fiber suspension: straight fibers of random direction.

    Parameters
    ----------
    shape : (3,) ints
        Volume shape (z, y, x), voxels.
    n_fibers : int
        Fibers to place (fewer if the volume fills up: random sequential addition gives up on a
        fiber after ``max_attempts`` placements).
    radius_vox : float
    length_vox : (min, max)
        Uniform range of fiber lengths, voxels.
    orientation : {"planar", "isotropic"}
        Directions uniform in the y-x plane (a mat lying in the slices, as in a short-fiber
        suspension that settled in layers, tilted out of the plane by at most 10 degrees), or
        uniform on the sphere.
    min_gap_vox, voxel_size_m, contrast_to_noise, blur_sigma_vox, seed, dtype
        As :func:`make_phantom`.

    Returns
    -------
    volume, truth : as :func:`make_phantom` (every fiber lies inside the volume).
    """
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(seed)
    shp = np.array(shape, dtype=float)
    r = float(radius_vox)
    margin = r + 1.5
    placed, pts_all = [], np.zeros((0, 3))
    tree = None
    for _ in range(int(n_fibers)):
        for _attempt in range(max_attempts):
            L = rng.uniform(*length_vox)
            if orientation == "planar":
                phi = rng.uniform(0, np.pi)
                el = np.radians(rng.uniform(-10.0, 10.0))
                d = np.array([np.sin(el), np.cos(el) * np.sin(phi), np.cos(el) * np.cos(phi)])  # z y x
            elif orientation == "isotropic":
                d = rng.normal(size=3)
                d /= np.linalg.norm(d)
            else:
                raise InputError(f"phantom: unknown orientation {orientation!r} (use 'planar' or 'isotropic')")
            c = rng.uniform(margin, shp - 1 - margin)
            a, b = c - 0.5 * L * d, c + 0.5 * L * d
            if np.any(np.minimum(a, b) < margin) or np.any(np.maximum(a, b) > shp - 1 - margin):
                continue
            line = np.linspace(a, b, max(2, int(np.ceil(L)) + 1))
            if tree is not None and np.isfinite(tree.query(line, k=1, distance_upper_bound=2 * r + min_gap_vox)[0]).any():
                continue
            placed.append(line)
            pts_all = np.vstack([pts_all, line])
            tree = cKDTree(pts_all)
            break
    vol = _render_vox(placed, [r] * len(placed), tuple(int(s) for s in shape), blur_sigma_vox=blur_sigma_vox,
                      contrast_to_noise=contrast_to_noise, seed=seed + 1, background=0.0, foreground=1.0,
                      dtype=dtype)
    truth = Polylines.from_list([voxel_to_xyz_m(l, voxel_size_m) for l in placed], r * voxel_size_m)
    truth.meta.update(voxel_size_m=float(voxel_size_m), radius_vox=r, seed=seed, orientation=orientation)
    return vol, truth


#: The harder quasi-parallel family (:func:`make_hard_phantom`): ranges drawn per seed.
HARD_FAMILY = {"n_fibers": 36, "shape": (160, 150, 150), "radius_vox": (4.0, 6.0), "contrast_to_noise": (3.0, 4.0),
               "touching_fraction": 0.4, "max_tilt_deg": 10.0}


def make_hard_phantom(seed: int, **overrides):
    """A phantom of the harder quasi-parallel family: 36 fibers, 40 % of them in pairs touching
    along their whole length, radius drawn from 4-6 voxels and contrast-to-noise from 3-4 per seed,
    mean directions tilted by up to 10 degrees (each of the two slopes within +-tan(10 deg)/sqrt(2)).

    ``overrides`` go to :func:`make_phantom`. Returns ``(volume, truth)``; ``truth.meta`` also
    records the drawn ``contrast_to_noise``.
    """
    f = HARD_FAMILY
    rng = np.random.default_rng(10_000 + seed)
    r = float(rng.uniform(*f["radius_vox"]))
    cnr = float(rng.uniform(*f["contrast_to_noise"]))
    kw = dict(n_fibers=f["n_fibers"], shape=f["shape"], radius_vox=r, contrast_to_noise=cnr,
              touching_fraction=f["touching_fraction"], max_tilt=np.tan(np.radians(f["max_tilt_deg"])) / np.sqrt(2),
              seed=seed)
    kw.update(overrides)
    vol, truth = make_phantom(**kw)
    truth.meta.update(contrast_to_noise=kw["contrast_to_noise"])
    return vol, truth
