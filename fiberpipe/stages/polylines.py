"""Stage ``input`` for small scenes: inline ``input.polylines`` (metres) -> ``fibers.h5``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fiberpipe.artifacts import write_fibers
from fiberpipe.config import Config
from fiberpipe.errors import ConfigError
from fiberpipe.polylines import Polylines


def run_inline_polylines(cfg: Config, out: Path, *, config_sha256: str = "") -> dict:
    if cfg.fiber.radius is None:
        raise ConfigError("input.polylines needs fiber.radius (e.g. '0.25 mm')", where=cfg.source_path)
    lines = [np.asarray(line, dtype=np.float64) for line in cfg.input.polylines]
    for i, line in enumerate(lines):
        if not np.all(np.isfinite(line)):
            raise ConfigError(f"input.polylines[{i}] has non-finite coordinates", where=cfg.source_path)
    fibers = Polylines.from_list(lines, cfg.fiber.radius)
    write_fibers(out, fibers, config_sha256=config_sha256)
    return {"fibers": fibers.n_fibers, "points": int(len(fibers.points_m))}
