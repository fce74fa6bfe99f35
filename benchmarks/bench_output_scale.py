"""Output at scale: the writers and ``fiberpipe post`` on a yarn's run of synthetic frames.

    python benchmarks/bench_output_scale.py runs/specimens/yarn-4000 --out runs/bench-output-4000

Meshes the specimen (``fiberpipe mesh`` of its ready config), writes ``simulation.h5`` and the VTU
frames of ``--frames`` frames in which the nodes are pressed affinely between the plates by the
config's loading displacement (positions only: the solver does not run, so no contact fields), with
a made-up cubic load in the history, then times ``fiberpipe post`` on them. Prints the sizes, the
CPU and wall times (this process and the post's, measured apart) and the load average.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import time
import types
from pathlib import Path

import numpy as np


def synthetic_result(mesh, gap_m: float, displacement_m: float, frames: int, rows: int = 2000):
    """Frames pressed affinely in y from the gap to gap − U, and a cubic load F ∝ (u/U)³ in the history."""
    end_s = displacement_m / (1000e-3 / 60)
    strain = np.linspace(0.0, displacement_m / gap_m, frames)
    positions = np.repeat(mesh.nodes_m[None], frames, axis=0)
    positions[:, :, 1] = gap_m - (gap_m - mesh.nodes_m[None, :, 1]) * (1 - strain[:, None])
    time_s = np.linspace(0.0, end_s, rows)
    lower = displacement_m * time_s / end_s
    force = 50.0 * (lower / displacement_m) ** 3
    history = {"time": time_s, "plate_displacement": np.column_stack([lower, np.zeros(rows)]),
               "plate_position": np.column_stack([lower, np.full(rows, gap_m)]),
               "plate_force": np.column_stack([force, force]),
               "energy": {"kinetic": np.zeros(rows), "strain": force * lower, "external": force * lower,
                          "residual": np.zeros(rows)}}
    return types.SimpleNamespace(frames_time=np.linspace(0.0, end_s, frames), frames_positions=positions,
                                 history=history, dt_s=1e-6, steps=int(end_s / 1e-6), wall_time_s=0.0,
                                 effects=["plates", "contact"], fields={})


def timed(call):
    """(result, wall s, CPU s of this process) of ``call()``."""
    wall, cpu = time.perf_counter(), time.process_time()
    result = call()
    return result, time.perf_counter() - wall, time.process_time() - cpu


def main(argv=None) -> int:
    import yaml

    from fiberpipe.artifacts import read_mesh
    from fiberpipe.stages.simulate import write_frames_vtk, write_simulation

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("specimen", type=Path, help="a folder of `fiberpipe specimen` (config.yaml, fibers.h5)")
    parser.add_argument("--out", type=Path, required=True, help="the run folder to write")
    parser.add_argument("--frames", type=int, default=24)
    args = parser.parse_args(argv)
    config = args.specimen / "config.yaml"
    fiberpipe = [sys.executable, "-m", "fiberpipe.cli", "-q"]
    subprocess.run([*fiberpipe, "mesh", str(config), "--out", str(args.out)], check=True)
    mesh = read_mesh(args.out / "mesh.h5")
    scene = yaml.safe_load(config.read_text())["scene"]
    result = synthetic_result(mesh, float(scene["plates"]["upper_position"]), float(scene["loading"]["displacement"]),
                              args.frames)
    _, h5_wall, h5_cpu = timed(lambda: write_simulation(args.out / "simulation.h5", mesh, result, effects=result.effects))
    _, vtu_wall, vtu_cpu = timed(lambda: write_frames_vtk(args.out, mesh, result.frames_time, result.frames_positions))
    vtu_bytes = sum(f.stat().st_size for f in (args.out / "frames").glob("*.vtu")) / args.frames
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    wall = time.perf_counter()
    subprocess.run([*fiberpipe, "post", str(config), "--out", str(args.out), "--force"], check=True)
    post_wall = time.perf_counter() - wall
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    post_cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    print(f"{mesh.n_fibers} fibers, {mesh.nodes_m.shape[0]} nodes, {args.frames} frames; load average "
          f"{os.getloadavg()[0]:.1f}")
    print(f"simulation.h5 {(args.out / 'simulation.h5').stat().st_size / 1e6:.1f} MB, written in {h5_cpu:.1f} s CPU "
          f"({h5_wall:.1f} s wall)")
    print(f"VTU frames {vtu_bytes / 1e6:.1f} MB each, {args.frames} written in {vtu_cpu:.1f} s CPU ({vtu_wall:.1f} s wall)")
    print(f"fiberpipe post {post_cpu:.1f} s CPU ({post_wall:.1f} s wall), peak RSS {after.ru_maxrss / 1e3:.0f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
