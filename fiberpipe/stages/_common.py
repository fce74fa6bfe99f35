"""Small helpers shared by the stage functions."""

from __future__ import annotations

from pathlib import Path

from fiberpipe.artifacts import file_sha256


def input_hashes(inputs: dict[str, Path]) -> dict[str, str]:
    """sha256 of each input artifact, recorded as provenance in the output's ``inputs`` attribute."""
    return {name: file_sha256(p) for name, p in inputs.items() if p is not None and Path(p).is_file()}
