"""Verification of the beam solver against analytical references (docs/verification.md).

``python -m fiberpipe.verification [--quick]`` prints the table and exits non-zero on a FAIL.
"""

from .cases import CASES, Row, run_all

__all__ = ["CASES", "Row", "run_all"]
