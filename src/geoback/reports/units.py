"""How numbers are shown to engineers: moduli in MPa (GPa from 1 GPa), displacements in mm, no
e-notation where a plain number reads as well, no float noise in tables.

The case's own units (kPa, m) stay in summary.json and in the CSV columns named without a unit;
report.md, the terminal report, the figures and the CSV columns named ``*_shown`` or with a unit in
brackets use these."""
from __future__ import annotations

import math

SIGNIFICANT = 12  # digits kept in CSV tables: the float's noise (-0.0011916000000000001) dropped


def shown(unit: str, value: float) -> tuple[float, str]:
    """(factor, unit) to show a quantity of `unit` whose size is about `value`: kPa in MPa from
    1 MPa and in GPa from 1 GPa, kPa/m likewise; anything else as it is ('-' when unitless)."""
    v = abs(value) if value == value else 0.0
    if unit == "kPa":
        return (1e-6, "GPa") if v >= 1e6 else (1e-3, "MPa") if v >= 1e3 else (1.0, "kPa")
    if unit == "kPa/m":
        return (1e-3, "MPa/m") if v >= 1e3 else (1.0, "kPa/m")
    return 1.0, unit or "-"


def number(v: float, digits: int = 6) -> str:
    """`digits` significant digits, without e-notation for 1e-3 <= |v| < 1e6 (12500, not 1.25e+04)."""
    if not isinstance(v, (int, float)) or not math.isfinite(v):
        return "∞" if v == math.inf else "-∞" if v == -math.inf else str(v)
    a = abs(v)
    if a == 0 or not 1e-3 <= a < 1e6:
        return f"{v:.{digits}g}"
    k = math.floor(math.log10(a)) + 1  # digits before the point
    if k >= digits:
        return f"{round(v, digits - k):.0f}"
    return f"{v:.{digits}g}"


def with_unit(v: float, unit: str, digits: int = 6) -> str:
    """The number and its unit (none when unitless)."""
    return number(v, digits) + ("" if unit in ("-", "") else f" {unit}")


def rounded(v, digits: int = SIGNIFICANT):
    """A float rounded to `digits` significant digits (CSV writes its shortest repr); others as they are."""
    if isinstance(v, bool) or not isinstance(v, (int, float)) and not hasattr(v, "dtype"):
        return v
    try:
        f = float(v)
    except (TypeError, ValueError):
        return v
    if not math.isfinite(f) or f == 0:
        return f
    return float(f"{f:.{digits}g}")
