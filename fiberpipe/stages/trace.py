"""Stage ``trace``: ``mask.h5`` (+ ``skeleton.h5``) -> ``fibers.h5`` (one mid-line per fiber)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from fiberpipe.artifacts import read_artifact, read_fibers, write_fibers, write_text_atomic
from fiberpipe.config import Config
from fiberpipe.stages._common import input_hashes
from fiberpipe.stages.skeletonize import eval_list


def run_trace(
    cfg: Config,
    mask_path: Path,
    out: Path,
    *,
    skeleton_path: Path | None = None,
    truth_path: Path | None = None,
    config_sha256: str = "",
) -> dict:
    from fiberpipe.imaging.trace import trace

    art = read_artifact(mask_path, "mask")
    mask = art["mask"]
    voxel_size = eval_list(art.attrs["voxel_size_m"])
    t = cfg.trace
    kwargs = dict(
        voxel_size_m=voxel_size if len(set(voxel_size)) > 1 else voxel_size[0],
        method=t.method,
        expected_radius_m=t.expected_radius or cfg.fiber.radius,
    )
    options = ("max_jump_vox", "max_skip", "min_length_vox", "smooth_sigma_vox") if t.method == "slices" else ("min_length_vox", "smooth_sigma_vox")
    kwargs.update({k: getattr(t, k) for k in options if getattr(t, k) is not None})
    inputs = {"mask": Path(mask_path)}
    if t.method == "skeleton":
        sk = read_artifact(skeleton_path, "skeleton")
        kwargs["skeleton"] = sk["skeleton"]
        kwargs["radius_vox"] = sk["radius_vox"]
        inputs["skeleton"] = Path(skeleton_path)
    fibers = trace(mask, **kwargs)
    write_fibers(out, fibers, config_sha256=config_sha256, inputs=input_hashes(inputs), attrs={"trace_method": t.method})
    figures = {
        "fibers": int(fibers.n_fibers),
        "mean_length_m": float(fibers.lengths_m().mean()) if fibers.n_fibers else 0.0,
        "mean_radius_m": float(fibers.radius_m.mean()) if fibers.n_fibers else 0.0,
    }
    if truth_path is not None and Path(truth_path).exists():
        figures["accuracy"] = trace_accuracy_report(out, truth_path, voxel_size[0], Path(out).with_name("trace_accuracy.json"))
    return figures


def trace_accuracy_report(fibers_path: Path, truth_path: Path, voxel_size_m: float, out_json: Path | None = None) -> dict:
    """Compare traced fibers with ground truth (the metrics of docs/imaging.md); optionally save as JSON."""
    from fiberpipe.imaging.accuracy import trace_accuracy

    acc = trace_accuracy(read_fibers(fibers_path), read_fibers(truth_path), voxel_size_m=voxel_size_m)
    acc = {k: (float(v) if isinstance(v, (np.floating, np.integer)) else v) for k, v in acc.items() if not isinstance(v, np.ndarray)}
    if out_json is not None:
        write_text_atomic(out_json, json.dumps(acc, indent=2, default=float))
    return acc
