"""Validation of the bundle-scale physics against published compaction laws (docs/validation.md).

``fiberpipe validate [--quick] [CASE ...]`` runs the virtual experiments of :data:`CASES` (one module
per case, each with a ``validate(quick)`` returning :class:`~fiberpipe.validation.rows.ValidationRow`),
writes a JSON summary and the generated section of docs/validation.md."""

from .registry import CASES, run_cases
from .rows import ValidationRow

__all__ = ["CASES", "ValidationRow", "run_cases"]
