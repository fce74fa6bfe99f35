"""Make the small sample phantom in data-samples/phantom-small/ (committed with its outputs).

Run from the repository root: ``python data-samples/make_samples.py``. Deterministic (seed 0).
14 curved quasi-parallel fibers of radius 4 voxels, a third of them in touching pairs, 150 slices
of 64 x 64 voxels; voxel 62.5 um so fibers are 0.5 mm in diameter (the study's) and 9.4 mm long.
Writes ``volume.tif`` (uint8, ImageJ voxel-size metadata) and ``truth.npz`` (points_m (P, 3) x y z
in m, offsets (F+1), radius_m (F); the fibers artifact layout of docs/outputs.md).
"""

from pathlib import Path

import numpy as np

from fiberpipe.imaging.io import save_volume_tif
from fiberpipe.imaging.phantom import make_phantom

OUT = Path(__file__).resolve().parent / "phantom-small"
PARAMS = dict(n_fibers=14, shape=(150, 64, 64), radius_vox=4.0, voxel_size_m=62.5e-6,
              touching_fraction=1 / 3, waviness_vox=2.0, contrast_to_noise=5.0, blur_sigma_vox=1.0,
              seed=0, dtype="uint8")


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    vol, truth = make_phantom(**PARAMS)
    save_volume_tif(OUT / "volume.tif", vol, PARAMS["voxel_size_m"])
    np.savez_compressed(OUT / "truth.npz", points_m=truth.points_m, offsets=truth.offsets,
                        radius_m=truth.radius_m, touching=truth.meta["touching"],
                        voxel_size_m=np.float64(PARAMS["voxel_size_m"]))
    print(f"wrote {OUT}/volume.tif {vol.shape} {vol.dtype} and truth.npz ({truth.n_fibers} fibers)")


if __name__ == "__main__":
    main()
