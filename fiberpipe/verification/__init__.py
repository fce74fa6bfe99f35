"""Verification of the beam solver against analytical references (SPEC section 8).

``python -m fiberpipe.verification [--quick]`` prints the table and exits non-zero on a FAIL.
"""

from .cases import CASES, Row, run_all

__all__ = ["CASES", "Row", "run_all"]
