"""One validation result: the reference (formula and source), its tolerance, the measured value.

A row is judged on the mean over its specimen seeds; the spread over the seeds is reported beside
it, and a row whose spread exceeds its tolerance says so in its note. A quick variant's row may
instead carry ``bounds``, its quick tolerance: the physical range every seed's value must lie in
(a sign, an exponent's range), looser than the full case's tolerance but able to fail."""

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
    ``bounds`` (lower, upper): the quick tolerance; the row passes when every value is finite and
    within them (``error`` is then the mean itself, ``tolerance`` unused).
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
    bounds: tuple | None = None

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
        if not self.relative or self.bounds is not None:
            return abs(self.measured)
        if self.reference == 0 or not math.isfinite(self.reference):
            return float("nan")
        return abs(self.measured - self.reference) / abs(self.reference)

    @property
    def passed(self) -> bool:
        if self.bounds is not None:
            values = np.asarray(self.values, float)
            return bool(values.size and np.all(np.isfinite(values))
                        and np.all((values >= self.bounds[0]) & (values <= self.bounds[1])))
        return bool(math.isfinite(self.error) and self.error <= self.tolerance)

    @property
    def spread_exceeds_tolerance(self) -> bool:
        """The seeds scatter more than the tolerance (relative to the reference, or absolute)."""
        if self.bounds is not None:
            return False
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
                "bounds": None if self.bounds is None else [float(b) for b in self.bounds],
                "data": self.data}
