"""Quantities with unit strings at the edges, SI floats inside.

A config value may be a bare number (taken as SI) or a string such as ``"0.5 mm"``,
``"15 GPa"`` or ``"1000 mm/min"``; :func:`to_si` checks its dimension with pint and returns
the SI magnitude.
"""

from __future__ import annotations

from functools import lru_cache

import pint

#: Dimension name -> pint dimensionality string, used to check a quantity's unit.
DIMENSIONS = {
    "length": "[length]",
    "time": "[time]",
    "rate": "1/[time]",
    "velocity": "[length]/[time]",
    "acceleration": "[length]/[time]**2",
    "pressure": "[mass]/[length]/[time]**2",
    "density": "[mass]/[length]**3",
    "force": "[mass]*[length]/[time]**2",
    "line_force": "[mass]/[time]**2",
    "stiffness": "[mass]/[time]**2",
    "stiffness_per_length": "[mass]/[length]/[time]**2",
    "energy": "[mass]*[length]**2/[time]**2",
    "angle": "",
    "dimensionless": "",
}

SI_UNITS = {
    "length": "m",
    "time": "s",
    "rate": "1/s",
    "velocity": "m/s",
    "acceleration": "m/s**2",
    "pressure": "Pa",
    "density": "kg/m**3",
    "force": "N",
    "line_force": "N/m",
    "stiffness": "N/m",
    "stiffness_per_length": "N/m**2",
    "energy": "J",
    "angle": "rad",
    "dimensionless": "",
}


@lru_cache(maxsize=1)
def ureg() -> pint.UnitRegistry:
    reg = pint.UnitRegistry()
    return reg


def _bare_number(value, what: str, expected: str) -> float | None:
    """``value`` as a float when it is a bare number (already SI), None when it is a string to parse
    with its unit; a boolean or another type is refused naming ``what``/``expected``. YAML 1.1 reads
    "1e-3" (no dot) as a string: a bare number in a string is still a number."""
    if isinstance(value, bool):
        raise ValueError(f"expected {what}, got a boolean")
    if isinstance(value, (int, float)):
        return float(value)
    if not isinstance(value, str):
        raise ValueError(f"expected {expected}, got {value!r}")
    try:
        return float(value)
    except ValueError:
        return None


def to_si(value, dimension: str) -> float:
    """Convert a number (already SI) or a unit string to an SI float of the given dimension.

    Parameters
    ----------
    value : float, int or str
        ``15e9``, ``"15 GPa"``, ``"1000 mm/min"``, ``"6 deg"``.
    dimension : str
        A key of :data:`DIMENSIONS`.

    Raises
    ------
    ValueError
        When the string does not parse or has the wrong dimension (message names both).
    """
    bare = _bare_number(value, f"a {dimension}", f"a number or a quantity string for a {dimension}")
    if bare is not None:
        return bare
    reg = ureg()
    try:
        q = reg.Quantity(value.strip())
    except Exception as exc:  # pint raises several types for bad strings
        raise ValueError(f"cannot read {value!r} as a {dimension} ({type(exc).__name__})") from None
    if not isinstance(q, reg.Quantity):
        return float(q)
    if dimension == "angle":
        if q.dimensionless:
            return float(q.to("rad").magnitude) if str(q.units) != "dimensionless" else float(q.magnitude)
        raise ValueError(f"{value!r} is not an angle")
    want = reg.parse_units(SI_UNITS[dimension]) if SI_UNITS[dimension] else reg.dimensionless
    if q.dimensionality != (1 * want).dimensionality:
        raise ValueError(
            f"{value!r} has units of {q.dimensionality}, but a {dimension} "
            f"(e.g. in {SI_UNITS[dimension] or 'no unit'}) is expected"
        )
    return float(q.to(want).magnitude)


def to_bytes(value) -> float:
    """An amount of memory in bytes: a bare number (bytes) or a string such as ``"4 GB"``,
    ``"512 MB"`` or ``"16 GiB"`` (decimal and binary prefixes, as pint reads them).

    Raises
    ------
    ValueError
        When the string does not parse or is not an amount of bytes (or bits).
    """
    what = "an amount of memory such as '4 GB'"
    bare = _bare_number(value, what, what)
    if bare is not None:
        return bare
    reg = ureg()
    try:
        q = reg.Quantity(value.strip())
        unit = str(q.units)
        if not ("byte" in unit or "bit" in unit):
            raise ValueError
        return float(q.to("byte").magnitude)
    except Exception:  # pint raises several types for bad strings
        raise ValueError(f"cannot read {value!r} as an amount of memory (e.g. '4 GB', '512 MB', '16 GiB')") from None
