"""Every config shipped in configs/ validates (keys, units, paths)."""

from pathlib import Path

import pytest

from fiberpipe.config import load_config

CONFIGS = sorted((Path(__file__).resolve().parents[1] / "configs").rglob("*.yaml"))
CONFIGS = [p for p in CONFIGS if "studies" not in p.parts]


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: str(p.relative_to(p.parents[1])))
def test_shipped_config_validates(path):
    cfg = load_config(path)
    for key in ("volume", "fibers", "truth"):
        value = getattr(cfg.input, key)
        if value is not None:
            assert Path(value).exists(), f"{path}: input.{key} = {value} does not exist"
