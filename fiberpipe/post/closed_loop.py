"""Close the loop: render a simulated frame as a CT volume, trace it again, measure the error.

This checks the imaging half against the mechanics half: the mid-lines the tracer recovers from a
rendered frame must lie within a voxel of the simulated ones.
"""

from __future__ import annotations

import numpy as np

from fiberpipe.errors import InputError
from fiberpipe.polylines import Polylines
from fiberpipe.post.positions import position_error


def frame_index(sim, frame: int) -> int:
    """``frame`` as an index from 0 (a negative one counts from the last frame); an InputError names
    the frames the simulation has when it has no such frame."""
    n = len(sim.frames_positions)
    if n == 0:
        raise InputError("the simulation has no frames (rerun it with solver.output_frames ≥ 1)")
    if not -n <= frame < n:
        raise InputError(f"frame {frame}: the simulation has {n} frames (0 to {n - 1}, or -{n} to -1 from the last)")
    return frame % n


def frame_polylines(sim, frame: int = -1) -> Polylines:
    """Mid-lines of a simulation frame (node positions of frame ``frame``, :func:`frame_index`), with
    the fiber radii."""
    return Polylines(np.array(sim.frames_positions[frame_index(sim, frame)]), sim.mesh.node_offsets.copy(),
                     sim.mesh.radius_m.copy())


def render_for_tracing(polylines: Polylines, voxel_size_m: float, *, margin_vox: int = 6, contrast_to_noise: float = 5.0,
                       blur_sigma_vox: float = 1.0, seed: int = 0, dtype="uint8"):
    """Render fibers into a volume whose grid covers them with a margin.

    Returns the volume (Z, Y, X) and the origin (x y z, m) of voxel (0, 0, 0), so that
    ``points_in_volume = points_m − origin``.
    """
    from fiberpipe.imaging.phantom import render_polylines

    r = float(np.max(polylines.radius_m))
    lo = polylines.points_m.min(axis=0) - r - margin_vox * voxel_size_m
    hi = polylines.points_m.max(axis=0) + r + margin_vox * voxel_size_m
    size_xyz = np.ceil((hi - lo) / voxel_size_m).astype(int) + 1
    shape_zyx = (int(size_xyz[2]), int(size_xyz[1]), int(size_xyz[0]))
    shifted = Polylines(polylines.points_m - lo, polylines.offsets, polylines.radius_m)
    vol = render_polylines(shifted, shape_zyx, voxel_size_m, blur_sigma_vox=blur_sigma_vox,
                           contrast_to_noise=contrast_to_noise, seed=seed, dtype=dtype)
    return vol, lo


def closed_loop_error(polylines: Polylines, voxel_size_m: float, **render_kw) -> dict:
    """Render → segment → trace → mean mid-line distance to ``polylines``, in voxels and metres."""
    from fiberpipe.imaging.segment import segment
    from fiberpipe.imaging.trace import trace

    vol, origin = render_for_tracing(polylines, voxel_size_m, **render_kw)
    mask, _ = segment(vol)
    traced = trace(mask, voxel_size_m=voxel_size_m, expected_radius_m=float(np.mean(polylines.radius_m)))
    traced = Polylines(traced.points_m + origin, traced.offsets, traced.radius_m)
    # distance from each traced point to the simulated mid-line (the traced line is shorter at the
    # ends, where the tracer stops a radius early, so measure from traced to simulated)
    err = position_error(traced.points_m, traced.offsets, polylines.points_m, polylines.offsets)
    return {
        "n_simulated": polylines.n_fibers,
        "n_traced": traced.n_fibers,
        "mean_error_m": err["mean_m"],
        "max_fiber_error_m": err["max_m"],
        "mean_error_vox": err["mean_m"] / voxel_size_m,
        "volume_shape": list(vol.shape),
    }
