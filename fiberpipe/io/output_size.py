"""The size of a run's output, estimated before the run starts, against the free disk space.

The estimate is an upper bound: the arrays as written before compression (the HDF5 frames and
histories are gzip-compressed, the VTU frames zlib-compressed; float64 positions shrink by 10–30 %),
plus the VTU's base64 encoding (4/3). A run that would not fit stops before its first step with a
one-line error naming the outputs and the key that sets their number (``solver.output_frames``).
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import NamedTuple

from fiberpipe.errors import ConfigError

FLOAT_BYTES = 8
#: per node and frame in simulation.h5: positions and, with contact, contact_force (3 + 3 floats)
H5_FLOATS_PER_NODE = 6
#: per node and frame in a VTU: points, displacement, contact_force (3 each), its magnitude and
#: radius (1 each) as float64, fiber_id as int32
VTU_NODE_BYTES = (3 + 3 + 3 + 1 + 1) * FLOAT_BYTES + 4
#: per element and frame in a VTU: connectivity (2 × int64), offset (int64), type (uint8), fiber_id (int32)
VTU_ELEMENT_BYTES = 3 * 8 + 1 + 4
BASE64 = 4 / 3
#: history columns recorded per row (time, plates, walls, energies, contacts ...): a generous count
HISTORY_COLUMNS = 40
#: a checkpoint holds positions, velocities, rotations and the contact state: about this many floats a node
CHECKPOINT_FLOATS_PER_NODE = 40


class OutputSize(NamedTuple):
    """Bytes of simulation.h5 (frames and history), the VTU frames and the checkpoint."""

    simulation_h5: int
    vtu_frames: int
    checkpoint: int

    @property
    def total(self) -> int:
        return self.simulation_h5 + self.vtu_frames + self.checkpoint


def estimate_output_bytes(n_nodes: int, n_elements: int, frames: int, history_rows: int = 2000) -> OutputSize:
    """An upper bound of what a run of ``frames`` output frames writes (module docstring)."""
    h5 = frames * n_nodes * H5_FLOATS_PER_NODE * FLOAT_BYTES + history_rows * HISTORY_COLUMNS * FLOAT_BYTES
    vtu = frames * int(BASE64 * (n_nodes * VTU_NODE_BYTES + n_elements * VTU_ELEMENT_BYTES))
    return OutputSize(int(h5), vtu, n_nodes * CHECKPOINT_FLOATS_PER_NODE * FLOAT_BYTES)


def check_free_space(run_dir: Path, n_nodes: int, n_elements: int, frames: int, *, where: str = "",
                     free_bytes: int | None = None) -> OutputSize:
    """Refuse, in one line naming the outputs and ``solver.output_frames``, a run whose output would
    not fit in the free space of ``run_dir``'s disk (``free_bytes``: that space, for tests)."""
    size = estimate_output_bytes(n_nodes, n_elements, frames)
    if free_bytes is None:
        probe = Path(run_dir)
        while not probe.exists() and probe != probe.parent:
            probe = probe.parent
        free_bytes = shutil.disk_usage(probe).free
    if size.total > free_bytes:
        raise ConfigError(
            f"solver.output_frames = {frames}: the run's output (simulation.h5 /frames/positions and /frames/contact_force "
            f"{_size(size.simulation_h5)}, frames/*.vtu {_size(size.vtu_frames)}, the checkpoint "
            f"{_size(size.checkpoint)}, for {n_nodes} nodes) would exceed the free disk space in {run_dir} "
            f"({_size(free_bytes)}): lower solver.output_frames or free space", where=where)
    return size


def _size(n_bytes: int) -> str:
    return f"{n_bytes / 1e9:.3g} GB" if n_bytes >= 1e9 else f"{n_bytes / 1e6:.3g} MB"
