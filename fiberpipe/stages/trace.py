"""Stage ``trace``: ``mask.h5`` (+ ``skeleton.h5``) -> ``fibers.h5`` (one mid-line per fiber)."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from fiberpipe.artifacts import read_artifact, read_fibers, write_fibers, write_json_atomic
from fiberpipe.config import MIN_FIBER_LENGTH_DIAMETERS, Config, element_length_m, min_fiber_length_m
from fiberpipe.errors import InputError
from fiberpipe.stages._common import input_hashes
from fiberpipe.stages.skeletonize import eval_list

log = logging.getLogger("fiberpipe")


def run_trace(
    cfg: Config,
    mask_path: Path,
    out: Path,
    *,
    skeleton_path: Path | None = None,
    truth_path: Path | None = None,
    config_sha256: str = "",
    volume_path: Path | None = None,
) -> dict:
    from fiberpipe.imaging.trace import trace
    from fiberpipe.stages._chunks import chunked
    from fiberpipe.stages.skeletonize import mask_shape

    if chunked(cfg, mask_shape(mask_path)):
        return run_trace_chunked(cfg, mask_path, out, truth_path=truth_path, config_sha256=config_sha256,
                                 volume_path=volume_path)
    art = read_artifact(mask_path, "mask")
    mask = art["mask"]
    voxel_size = eval_list(art.attrs["voxel_size_m"])
    t = cfg.trace
    check_voxel_size(cfg, voxel_size, t.expected_radius or cfg.fiber.radius)
    method, orient_mask = choose_method(cfg, mask, voxel_size)
    kwargs = dict(
        voxel_size_m=voxel_size if len(set(voxel_size)) > 1 else voxel_size[0],
        method=method,
        expected_radius_m=t.expected_radius or cfg.fiber.radius,
    )
    options = (("max_jump_vox", "max_skip", "min_length_vox", "smooth_sigma_vox") if method in ("slices", "dense")
               else ("min_length_vox", "smooth_sigma_vox"))
    kwargs.update({k: getattr(t, k) for k in options if getattr(t, k) is not None})
    inputs = {"mask": Path(mask_path)}
    if method == "skeleton" and skeleton_path is not None and Path(skeleton_path).exists():
        sk = read_artifact(skeleton_path, "skeleton")
        kwargs["skeleton"] = sk["skeleton"]
        kwargs["radius_vox"] = sk["radius_vox"]
        inputs["skeleton"] = Path(skeleton_path)
    if t.join_gap_vox is not None:
        kwargs["join_gap_vox"] = t.join_gap_vox
    if method == "dense" and volume_path is None:
        raise InputError("trace.method dense finds the fiber centres in the grey volume, and this run has none "
                         "(input.volume): set trace.method: slices")
    if method in ("slices", "dense"):
        kwargs["off_axis"] = t.off_axis
        if (t.grey or method == "dense") and volume_path is not None:
            kwargs["grey"] = load_grey(cfg, volume_path, mask.shape)
            inputs["volume"] = Path(volume_path)
    fibers = trace(mask, **kwargs)
    off_axis = fibers.meta.get("off_axis") or {}
    warn_off_axis(off_axis, t.off_axis)
    return finish_trace(cfg, fibers, method, orient_mask, off_axis, inputs, out, mask, voxel_size,
                        truth_path=truth_path, config_sha256=config_sha256)


def warn_off_axis(off_axis: dict, mode: str) -> None:
    """One warning line per volume axis a region of the fibers runs along besides the slicing axis."""
    for ax, info in off_axis.items():
        if ax == "oblique":
            from fiberpipe.imaging.trace import DENSE_MAX_TILT_DEG

            log.warning("trace: %d tracks (%.0f voxels long in all) run more than %g deg off the slicing axis "
                        "(a +-45 deg ply): left out", info["fibers"], info["length_vox"], DENSE_MAX_TILT_DEG)
            continue
        oblique = f", {info['oblique']} tracks off its axis left out" if info.get("oblique") else ""
        log.warning("trace: %.0f %% of the fiber volume runs along %s, across the slicing axis (a cross ply or a tow "
                    "lying in the slices): %s (%d fibers%s); trace.off_axis: %s", 100 * info["volume_fraction"],
                    ax, info["action"], info["fibers"], oblique, "drop leaves it out" if mode == "trace"
                    else "trace follows it")


def finish_trace(cfg: Config, fibers, method: str, orient_mask: dict, off_axis: dict, inputs: dict, out: Path, mask,
                 voxel_size, *, truth_path: Path | None = None, config_sha256: str = "") -> dict:
    """What the trace stage does after tracing, in memory or chunked: folds cut, short fibers
    dropped, ``fibers.h5``, ``orientation.json``, the accuracy against ground truth, the pictures
    (``mask``: an array or a dataset on disk, read three slices), the figures."""
    from fiberpipe.imaging.orientation import fiber_orientation

    t = cfg.trace
    radius = fiber_radius_m(cfg, fibers)
    fibers, folds = split_folds_for_mesh(cfg, fibers, radius)
    min_length = min_length_m(cfg, radius)
    fibers, dropped = drop_short_fibers(fibers, min_length, "trace.min_length",
                                        None if cfg.trace.min_length is not None else
                                        f"{MIN_FIBER_LENGTH_DIAMETERS:g} fiber diameters, at least two mesh elements")
    write_fibers(out, fibers, config_sha256=config_sha256, inputs=input_hashes(inputs), attrs={"trace_method": method})
    orientation = {"mask": orient_mask, "fibers": fiber_orientation(fibers)}
    write_json_atomic(Path(out).with_name("orientation.json"), orientation)
    of = orientation["fibers"]
    figures = {
        "method": method,
        "aligned_fraction_45deg_mask": orient_mask.get("aligned_fraction_45deg"),
        "orientation": {k: of[k] for k in ("tensor", "eigenvalues", "dominant_axis_xyz", "median_angle_deg",
                                           "aligned_fraction_45deg", "angle_histogram") if k in of},
        "fibers": int(fibers.n_fibers),
        "joined_gaps": int(fibers.meta.get("n_joins", 0)),
        "cut_folds": folds,
        "dropped_short_fibers": dropped,
        "min_length_m": min_length,
        "element_length_m": element_length_m(cfg.mesh, radius),
        "off_axis": off_axis,
        "mean_length_m": float(fibers.lengths_m().mean()) if fibers.n_fibers else 0.0,
        "mean_radius_m": float(fibers.radius_m.mean()) if fibers.n_fibers else 0.0,
        "median_radius_m": float(np.median(fibers.radius_m)) if fibers.n_fibers else 0.0,
    }
    truth, matches = None, None
    if truth_path is not None and Path(truth_path).exists():
        figures["accuracy"] = trace_accuracy_report(out, truth_path, voxel_size[0], Path(out).with_name("trace_accuracy.json"))
        truth, matches = read_fibers(truth_path), figures["accuracy"].get("matches")
    if t.pictures and fibers.n_fibers:
        figures["pictures"] = write_pictures(Path(out).parent, mask, fibers, voxel_size, orientation,
                                             axis=int(fibers.meta.get("axis", 0) or 0), truth=truth, matches=matches)
    return figures


def write_pictures(run_dir: Path, mask, fibers, voxel_size, orientation: dict, *, axis: int = 0, truth=None,
                   matches=None) -> list[str]:
    """The tracing check pictures in the run folder: slices at three depths with the traced centres
    and radii over the mask (``trace_slices.png``; with ground truth, misses and false tracks
    marked), the mid-lines in 3D (``trace_midlines.png``), the orientation histogram
    (``orientation.png``). Returns their file names."""
    from fiberpipe.imaging.overlay import midlines_3d_png, orientation_png, slice_overlay_png

    names = ["trace_slices.png", "trace_midlines.png", "orientation.png"]
    slice_overlay_png(run_dir / names[0], mask, fibers, voxel_size, axis=axis, truth=truth, matches=matches)
    midlines_3d_png(run_dir / names[1], fibers)
    orientation_png(run_dir / names[2], orientation)
    return names


def load_grey(cfg: Config, volume_path: Path, shape) -> np.ndarray:
    """The input volume again (``trace.grey``), checked against the mask's shape."""
    from fiberpipe.imaging.io import load_volume

    inp = cfg.input
    vol, _, _ = load_volume(volume_path, voxel_size_m=inp.voxel_size or 1.0, dataset=inp.dataset,
                            shape=tuple(inp.shape) if inp.shape else None, dtype=inp.dtype)
    if vol.shape != tuple(shape):
        raise InputError(f"trace.grey: the volume {volume_path} has shape {vol.shape}, the mask {tuple(shape)}",
                         where=str(volume_path))
    return vol


def fiber_radius_m(cfg: Config, fibers) -> float:
    """The radius the scan-derived length defaults follow: ``fiber.radius``, else the traced fibers'
    median radius (m)."""
    if cfg.fiber.radius is not None:
        return float(cfg.fiber.radius)
    return float(np.median(fibers.radius_m)) if fibers.n_fibers else 0.0


def min_length_m(cfg: Config, radius_m: float) -> float:
    """``trace.min_length``, by default derived from the fiber radius (config.min_fiber_length_m)."""
    return min_fiber_length_m(cfg.trace, cfg.mesh, radius_m)


def check_voxel_size(cfg: Config, voxel_size, radius_m: float | None) -> None:
    """A nominal radius (``trace.expected_radius`` or ``fiber.radius``) that spans less than 1.5
    voxels across the fibers is a one-line error: no tracer resolves such fibers, and it usually
    means a voxel size in the wrong unit."""
    if radius_m is None:
        return
    diameter_vox = 2.0 * float(radius_m) / float(min(voxel_size))
    if diameter_vox < MIN_DIAMETER_VOX:
        key = "trace.expected_radius" if cfg.trace.expected_radius else "fiber.radius"
        raise InputError(f"input.voxel_size = {min(voxel_size) * 1e6:.4g} um makes the fibers ({key} = "
                         f"{radius_m * 1e6:.4g} um) {diameter_vox:.2g} voxels across, thinner than {MIN_DIAMETER_VOX:g}: "
                         "check the voxel size and its unit")


#: Fibers thinner than this many voxels across are not traced (an error naming the voxel size).
MIN_DIAMETER_VOX = 1.5


def choose_method(cfg: Config, mask, voxel_size) -> tuple[str, dict]:
    """The tracer to run and the mask's orientation distribution.

    ``trace.method: auto`` picks ``dense`` on a dense pack of thin fibers (:func:`dense_pack`) that
    is quasi-parallel or runs at least half along volume axes, else ``slices`` when at least
    ``trace.min_aligned_fraction`` of the fiber volume runs within 45 deg of one volume axis, else
    ``skeleton``; an explicit ``slices`` on fibers that are not quasi-parallel runs, with one
    warning line naming the key.
    """
    from fiberpipe.imaging.orientation import is_quasi_parallel, mask_orientation

    t = cfg.trace
    orient = mask_orientation(mask, voxel_size)
    # no measurable orientation (a mask too thin for the structure tensor): the slices tracer, as before auto
    # fibers along volume axes (a cross ply) are traced region by region along their own axis
    along_axes = float(orient.get("axis_aligned_fraction_30deg", 0.0)) >= t.min_aligned_fraction
    parallel = is_quasi_parallel(orient, t.min_aligned_fraction) or along_axes or not orient.get("n_samples")
    frac = 100 * float(orient.get("aligned_fraction_45deg", 0.0))
    if t.method == "auto":
        # a dense pack's mask is one merged region whose skeleton cannot separate its fibers: the
        # dense tracer takes it, region by region, whenever most of it runs along volume axes
        along = float(orient.get("axis_aligned_fraction_30deg", 0.0)) >= DENSE_MIN_AXIS_ALIGNED_FRACTION
        method = "dense" if (parallel or along) and dense_pack(mask, orient) else "slices" if parallel else "skeleton"
        log.info("trace: %.0f %% of the fiber volume within 45 deg of axis %s: method %s", frac,
                 orient.get("nearest_volume_axis"), method)
        return method, orient
    if t.method == "slices" and not parallel:
        log.warning("trace: only %.0f %% of the fiber volume runs within 45 deg of one volume axis (below "
                    "trace.min_aligned_fraction = %g): the slices tracer needs quasi-parallel fibers; set "
                    "trace.method: skeleton (or auto)", frac, t.min_aligned_fraction)
    return t.method, orient


#: ``trace.method: auto`` picks the dense tracer on a dense pack when at least this share of the fiber
#: volume runs within 30 deg of a volume axis (a cross ply: each ply along its own axis).
DENSE_MIN_AXIS_ALIGNED_FRACTION = 0.5


def dense_pack(mask, orient: dict) -> bool:
    """Whether a quasi-parallel scan is a dense pack of thin fibers (``trace.method: auto`` then
    picks ``dense``): the mask's volume fraction and its radius across the dominant axis
    (:func:`fiberpipe.imaging.dense.is_dense_pack`). ``mask``: an array, or a chunked mask's
    :class:`fiberpipe.imaging.trace_chunked.StridedSample`, read by strided boxes and 16 slices
    across the axis, so the chunked stage judges as the in-memory one (the same slices, the same
    sample up to the volume of :data:`DENSE_SAMPLE_VOXELS`)."""
    from fiberpipe.imaging.dense import is_dense_pack
    from fiberpipe.imaging.trace import estimate_radius_vox
    from fiberpipe.imaging.trace_chunked import _Block

    ax = {"z": 0, "y": 1, "x": 2}.get(orient.get("nearest_volume_axis"), 0)
    step = max(2, int(np.ceil((float(np.prod(mask.shape)) / DENSE_SAMPLE_VOXELS) ** (1.0 / 3.0))))
    sample = np.asarray(mask[::step, ::step, ::step])
    fraction = float(np.count_nonzero(sample)) / max(1, sample.size)
    if fraction < 0.3:
        return False
    if isinstance(mask, np.ndarray):
        mask_t = mask.transpose((ax,) + tuple(i for i in range(3) if i != ax))
    else:  # the slices across the axis, read one at a time from the dataset on disk
        mask_t = _Block(mask.arr, 0, mask.shape[ax], axis=ax, read_ahead=1)
    try:
        radius = estimate_radius_vox(mask_t, np.ones(2))
    except InputError:
        return False
    return is_dense_pack(fraction, radius)


#: The volume fraction of :func:`dense_pack` is read on a strided sample of at most about this many
#: voxels (every second voxel along each axis below it).
DENSE_SAMPLE_VOXELS = 16_000_000


def split_folds_for_mesh(cfg: Config, fibers, radius_m: float):
    """Cut traced fibers where they fold back (a turn above 90 deg between two consecutive mesh
    elements, nodes placed as the mesh stage places them), which the mesh stage would refuse."""
    from fiberpipe.imaging.fragments import split_folds
    from fiberpipe.model.mesh import resample_polyline

    if not fibers.n_fibers:
        return fibers, 0
    el, sm = element_length_m(cfg.mesh, radius_m), cfg.mesh.smooth_sigma
    return split_folds(fibers, lambda p: resample_polyline(p, el, smooth_sigma_m=sm), max_turn_deg=90.0)


def drop_short_fibers(fibers, min_length: float, key: str, default_of: str | None = None):
    """Drop fibers shorter than ``min_length`` (m), logging one warning line that names ``key``
    (``default_of``: what the value defaults to when the config leaves ``key`` unset).

    Returns the kept fibers and the number dropped. Every fiber too short is an InputError (there
    is nothing left to mesh).
    """
    from fiberpipe.imaging.fragments import drop_short

    kept, dropped = drop_short(fibers, min_length)
    if len(dropped) and kept.n_fibers == 0:
        origin = f" (unset: {default_of}; a length without a unit is in metres)" if default_of else ""
        raise InputError(f"all {fibers.n_fibers} fibers are shorter than {key} = {min_length * 1e3:.3g} mm{origin} "
                         f"(longest {fibers.lengths_m().max() * 1e3:.3g} mm); lower {key}")
    if len(dropped):
        log.warning("%s: dropped %d of %d fibers shorter than %s = %.3g mm", key.split(".")[0], len(dropped),
                    fibers.n_fibers, key, min_length * 1e3)
    return kept, int(len(dropped))


def trace_accuracy_report(fibers_path: Path, truth_path: Path, voxel_size_m: float, out_json: Path | None = None) -> dict:
    """Compare traced fibers with ground truth (the metrics of docs/imaging.md); optionally save as JSON."""
    from fiberpipe.imaging.accuracy import trace_accuracy

    acc = trace_accuracy(read_fibers(fibers_path), read_fibers(truth_path), voxel_size_m=voxel_size_m)
    acc = {k: (float(v) if isinstance(v, (np.floating, np.integer)) else v) for k, v in acc.items() if not isinstance(v, np.ndarray)}
    if out_json is not None:
        write_json_atomic(out_json, acc)
    return acc


def run_trace_chunked(cfg: Config, mask_path: Path, out: Path, *, truth_path: Path | None = None,
                      config_sha256: str = "", volume_path: Path | None = None) -> dict:
    """The trace stage block by block (``chunks``): the orientation measured on a strided sample of
    ``mask.h5`` (read a sampled slice at a time), then the slices tracer
    (:func:`fiberpipe.imaging.trace_chunked.trace_chunked`) in blocks of ``chunks.slices`` slices
    across the volume axis nearest the fibers' direction, on a Dask cluster when
    ``chunks.scheduler`` is set; the same artifacts as the in-memory path.

    The skeleton tracer needs the whole skeleton and is refused. Fibers along a second volume axis
    (a cross ply) are split off by their local axis as in memory (``trace.off_axis``), slab by slab
    (:func:`_trace_regions_chunked`)."""
    from fiberpipe.artifacts import open_checked
    from fiberpipe.imaging.orientation import axis_fractions
    from fiberpipe.imaging._dask import connect
    from fiberpipe.imaging.trace_chunked import SliceSource, StridedSample, trace_chunked

    t = cfg.trace
    with open_checked(mask_path, "mask") as f:
        voxel_size = eval_list(f.attrs["voxel_size_m"])
    check_voxel_size(cfg, voxel_size, t.expected_radius or cfg.fiber.radius)
    src = SliceSource(mask_path, "mask")
    sample = StridedSample(src.open())
    method, orient_mask = choose_method(cfg, sample, voxel_size)
    if method == "skeleton":
        frac = 100 * float(orient_mask.get("aligned_fraction_45deg", 0.0))
        why = ("trace.method is skeleton" if t.method == "skeleton" else
               f"only {frac:.0f} % of the fiber volume runs within 45 deg of one volume axis, so trace.method auto "
               "picks the skeleton tracer")
        raise InputError(f"{why}, which holds the whole skeleton in memory; the chunked trace stage runs the slices "
                         "tracer only: set trace.method: slices, or chunks.mode: off", where=str(mask_path))
    axis = {"z": 0, "y": 1, "x": 2}.get(orient_mask.get("nearest_volume_axis"), 0) if orient_mask.get("n_samples") else 0
    fr = axis_fractions(sample, voxel_size)
    split = any(b != axis and fr[b] >= OFF_AXIS_MIN_FRACTION for b in range(3))
    grey, inputs = None, {"mask": Path(mask_path)}
    if (t.grey or method == "dense") and volume_path is not None:
        grey = grey_source(cfg, volume_path, src.shape)
        inputs["volume"] = Path(volume_path)
    opts = {k: getattr(t, k) for k in ("max_jump_vox", "max_skip", "min_length_vox", "smooth_sigma_vox")
            if getattr(t, k) is not None}
    join = {"join_gap_vox": t.join_gap_vox} if t.join_gap_vox is not None else {}
    vs = voxel_size if len(set(voxel_size)) > 1 else voxel_size[0]
    with connect(cfg.chunks.scheduler) as client:
        kw = dict(expected_radius_m=t.expected_radius or cfg.fiber.radius, block=cfg.chunks.slices,
                  scheduler=client, grey=grey, join=join, **opts)
        if method == "dense" and grey is not None:
            kw["radius_from"] = "grey"
        if split:
            fibers = _trace_regions_chunked(cfg, src, vs, axis, Path(out).with_name("trace_regions.tmp.h5"), kw)
        else:
            fibers = trace_chunked(src, vs, axis=axis, **kw)
    off_axis = fibers.meta.get("off_axis") or {}
    fibers.meta["off_axis"] = off_axis
    warn_off_axis(off_axis, t.off_axis)
    try:
        figures = finish_trace(cfg, fibers, method, orient_mask, off_axis, inputs, out, src.open(), voxel_size,
                               truth_path=truth_path, config_sha256=config_sha256)
    finally:
        src.close()
        if grey is not None:
            grey.close()
    figures.update(chunked=True, slicing_axis="zyx"[axis], blocks=int(fibers.meta.get("blocks", 0)))
    return figures


#: Share of the fiber volume along a second volume axis above which the chunked trace stage splits
#: the regions (the in-memory tracer's ``off_axis_min_fraction``).
OFF_AXIS_MIN_FRACTION = 0.02


def _trace_regions_chunked(cfg: Config, src, voxel_size, axis: int, scratch: Path, kw: dict):
    """A cross ply, chunked: every fiber voxel labelled with its fibers' volume axis slab by slab into
    the scratch file ``scratch`` (removed afterwards), then the chunked slices tracer on each region
    of at least :data:`OFF_AXIS_MIN_FRACTION` of the fiber volume along its own axis
    (``trace.off_axis: trace``) or the other regions left out (``drop``), the rest along ``axis``."""
    import h5py

    from fiberpipe.imaging._util import voxel_size_zyx
    from fiberpipe.imaging.regions_chunked import RegionSource, axis_labels_chunked
    from fiberpipe.imaging.trace import add_oblique, combine_region_parts, region_info
    from fiberpipe.imaging.trace_chunked import SliceSource, trace_chunked
    from fiberpipe.stages._chunks import create_volume_dataset

    t, grey = cfg.trace, kw.get("grey")
    r_vox = (None if kw.get("expected_radius_m") is None
             else float(kw["expected_radius_m"]) / float(voxel_size_zyx(voxel_size).min()))
    try:
        with h5py.File(scratch, "w") as f:
            ds = create_volume_dataset(f, "labels", src.shape, np.uint8, "1")
            fr = axis_labels_chunked(src.open(), ds, voxel_size, slab=cfg.chunks.slices, halo=cfg.chunks.halo_vox,
                                     grey=None if grey is None else (grey.open() if hasattr(grey, "open") else grey),
                                     radius_vox=r_vox)
        others = [b for b in range(3) if b != axis and fr[b] >= OFF_AXIS_MIN_FRACTION]
        labels = SliceSource(scratch, "labels")
        parts = [trace_chunked(RegionSource(src, labels, [c for c in range(3) if c not in others]), voxel_size,
                               axis=axis, **kw)]
        if kw.get("expected_radius_m") is None and kw.get("radius_from") == "grey":
            # as in memory: the other regions traced at the main region's grey radius
            in_plane = float(np.delete(np.asarray(voxel_size_zyx(voxel_size), dtype=float), axis).min())
            kw = dict(kw, expected_radius_m=float(parts[0].meta["radius_vox_estimate"]) * in_plane)
        info = {}
        for b in others:
            if t.off_axis == "trace":
                parts.append(trace_chunked(RegionSource(src, labels, [b]), voxel_size, axis=b, **kw))
            info["zyx"[b]] = region_info(fr[b], parts[-1] if t.off_axis == "trace" else None)
        labels.close()
        add_oblique(info, parts)
        return combine_region_parts(parts, info) if info else parts[0]
    finally:
        scratch.unlink(missing_ok=True)


def grey_source(cfg: Config, volume_path: Path, shape):
    """The input volume as a slab-by-slab source (``trace.grey``, chunked), checked against the mask's shape."""
    from fiberpipe.imaging.volume_source import chunkable, open_volume_source

    if not chunkable(volume_path):
        raise InputError("trace.grey reads the input volume again, slab by slab when chunked, and this format is "
                         "read whole: convert it to HDF5 or Zarr, or set trace.grey: false", where=str(volume_path))
    inp = cfg.input
    src, _, _ = open_volume_source(volume_path, dataset=inp.dataset, shape=tuple(inp.shape) if inp.shape else None,
                                   dtype=inp.dtype)
    if tuple(src.shape) != tuple(shape):
        raise InputError(f"trace.grey: the volume {volume_path} has shape {tuple(src.shape)}, the mask {tuple(shape)}",
                         where=str(volume_path))
    return src
