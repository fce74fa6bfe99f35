"""One validation result: the reference (formula and source), its tolerance, the measured value.

A row is judged on the mean over its specimen seeds; the spread over the seeds is reported beside
it, and a row whose spread exceeds its tolerance says so in its note."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class ValidationRow:
    """One checked quantity of a validation case.

    ``reference``: the value the law gives (its formula and published source in ``source``);
    ``measured``: the mean over ``values`` (one per specimen seed, or one for a deterministic case);
    ``error``: |measured − reference| / |reference|, or, when ``relative`` is False, the measured
    value itself against an upper bound ``tolerance`` (e.g. a ratio that must stay below 5 %).
    ``status``: PASS / FAIL; ``informational`` rows are measured and shown but do not set the exit
    status (a law that fiberpipe's specimen is known not to follow in that regime, with its note).
    """

    case: str
    quantity: str
    reference: float
    values: list
    tolerance: float
    source: str
    unit: str = ""
    relative: bool = True
    informational: bool = False
    note: str = ""
    data: dict = field(default_factory=dict)

    @property
    def measured(self) -> float:
        return float(np.mean(self.values)) if len(self.values) else float("nan")

    @property
    def spread(self) -> float:
        """Half the range over the seeds (0 for one value)."""
        v = np.asarray(self.values, float)
        v = v[np.isfinite(v)]
        return float((v.max() - v.min()) / 2) if v.size > 1 else 0.0

    @property
    def error(self) -> float:
        if not self.relative:
            return abs(self.measured)
        if self.reference == 0 or not math.isfinite(self.reference):
            return float("nan")
        return abs(self.measured - self.reference) / abs(self.reference)

    @property
    def passed(self) -> bool:
        return bool(math.isfinite(self.error) and self.error <= self.tolerance)

    @property
    def spread_exceeds_tolerance(self) -> bool:
        """The seeds scatter more than the tolerance (relative to the reference, or absolute)."""
        scale = abs(self.reference) if self.relative and self.reference else 1.0
        return len(self.values) > 1 and self.spread / scale > self.tolerance

    @property
    def status(self) -> str:
        if self.informational:
            return "agrees (info)" if self.passed else "departs (info)"
        return "PASS" if self.passed else "FAIL"

    def as_dict(self) -> dict:
        return {"case": self.case, "quantity": self.quantity, "reference": self.reference, "unit": self.unit,
                "source": self.source, "values": [float(v) for v in self.values], "measured": self.measured,
                "spread": self.spread, "seeds": len(self.values), "error": self.error,
                "tolerance": self.tolerance, "relative": self.relative, "status": self.status,
                "passed": self.passed, "informational": self.informational,
                "spread_exceeds_tolerance": self.spread_exceeds_tolerance, "note": self.note,
                "data": self.data}
