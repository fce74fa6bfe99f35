"""The mask's fiber orientation: fiberpipe's structure tensor (``orientation.mask_orientation``)
against the ``structure-tensor`` package (Skielex/DTU, ``structure_tensor_3d`` + ``eig_special_3d``),
for speed and accuracy, on short-fiber phantoms with known fibers.

Usage (from the repository root; ``pip install structure-tensor``)::

    python benchmarks/bench_structure_tensor.py [--out FILE.md]

Both read the same strided subsample of the mask (the one ``mask_orientation`` takes, a
radius of about 3 samples), smoothed by sigma 1 sample and integrated over rho = the subsample's
fiber radius, and weight each strong voxel's direction (the eigenvector of the smallest eigenvalue)
by the tensor's trace. Accuracy: the largest difference between the orientation tensor A = <t t^T>
and the true fibers' (``orientation.fiber_orientation``, each segment weighted by its length).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]  # the source checkout
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402


def package_tensor(mask: np.ndarray, voxel_size_m: float, max_voxels: int = 2_000_000) -> np.ndarray:
    """The orientation tensor by the structure-tensor package on mask_orientation's subsample."""
    from structure_tensor import eig_special_3d, structure_tensor_3d

    from fiberpipe.imaging.orientation import _subsample
    from fiberpipe.imaging._util import voxel_size_zyx

    v = voxel_size_zyx(voxel_size_m)
    step = max(1, int(np.ceil((mask.size / float(max_voxels)) ** (1.0 / 3.0))))
    sub, scale, r = _subsample(mask, v, step)
    if r > 6.0:
        step *= int(r // 3.0)
        sub, scale, r = _subsample(mask, v, step)
    rho = float(np.clip(r, 1.0, 6.0))
    # isotropic voxels only (the package takes no spacing); its x is the volume's last axis
    S = structure_tensor_3d(sub.astype(np.float32), 1.0, rho, truncate=3.0)  # (6, Z, Y, X)
    tr = S[0] + S[1] + S[2]
    strong = tr > 0.1 * float(np.percentile(tr[tr > 0], 90))
    _, vec = eig_special_3d(S[:, strong], full=False)  # (3, n): the smallest eigenvalue's vector, x y z
    ok = np.isfinite(vec).all(axis=0)  # its closed form divides by zero where the tensor is degenerate
    t = vec[:, ok].T.astype(np.float64)
    w = tr[strong][ok].astype(np.float64)
    return np.einsum("n,ni,nj->ij", w, t, t) / w.sum()


def main(argv=None) -> None:
    from fiberpipe.imaging.orientation import fiber_orientation, mask_orientation
    from fiberpipe.imaging.phantom import make_short_fiber_phantom
    from fiberpipe.imaging.segment import segment

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    rows = ["| phantom | true eigenvalues | fiberpipe: max tensor error | time (s) | structure-tensor: max tensor "
            "error | time (s) |", "| --- | --- | --- | --- | --- | --- |"]
    for orientation in ("planar", "isotropic"):
        for seed in (0, 1):
            vol, truth = make_short_fiber_phantom(shape=(100, 180, 270), n_fibers=150, radius_vox=2.7,
                                                  orientation=orientation, seed=seed)
            vs = truth.meta.get("voxel_size_m", 10e-6)
            mask, _ = segment(vol)
            A_true = np.asarray(fiber_orientation(truth)["tensor"])
            t0 = time.perf_counter()
            ours = np.asarray(mask_orientation(mask, vs)["tensor"])
            t1 = time.perf_counter()
            theirs = package_tensor(mask, vs)
            t2 = time.perf_counter()
            ev = np.sort(np.linalg.eigvalsh(A_true))[::-1]
            rows.append(f"| {orientation}, seed {seed} | {ev[0]:.3f} {ev[1]:.3f} {ev[2]:.3f} | "
                        f"{np.abs(ours - A_true).max():.3f} | {t1 - t0:.2f} | {np.abs(theirs - A_true).max():.3f} | "
                        f"{t2 - t1:.2f} |")
            print(rows[-1], flush=True)
    text = "\n".join(rows) + "\n"
    print(text)
    if a.out:
        a.out.write_text(text)


if __name__ == "__main__":
    main()
