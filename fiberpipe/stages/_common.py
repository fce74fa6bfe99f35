"""Small helpers shared by the stage functions."""

from __future__ import annotations

from pathlib import Path

from fiberpipe.artifacts import input_sha256


def input_hashes(inputs: dict[str, Path]) -> dict[str, str]:
    """sha256 of each input (:func:`fiberpipe.artifacts.input_sha256`: files, MetaImage pairs, TIFF and
    Zarr folders), recorded as provenance in the output's ``inputs`` attribute."""
    return {name: d for name, p in inputs.items() if p is not None and (d := input_sha256(Path(p))) is not None}
