"""How numbers are shown to engineers (the foundation: reports and the diagnosis both use it): moduli in MPa (GPa from 1 GPa), displacements in mm, no
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


# ------------------------------------------------------------------ a named parameter, one unit per kind
# (the diagnosis' tables: the same unit for a value, its std, its interval and a detectable size)
# How `diagnose` shows a quantity to people: one engineering unit per kind of quantity, the same
# for a value, its std, its interval and a detectable size, everywhere in diagnosis.md.
#
# | SI unit (the case's) | shown in | for |
# |---|---|---|
# | kPa | MPa | every modulus, the ground's and the lining's alike (a shotcrete 30 GPa is 30000 MPa) |
# | kPa | kPa | a strength: cohesion c', tension cut-off |
# | kPa/m | MPa/m | a modulus gradient |
# | rad | mrad | an inclinometer's bias shift, a deflectometer's end rotation (never mm/m beside rad) |
# | m | mm | an instrument's reference-end movement (A, B, D) |
# | m | m | a depth offset, a boundary depth |
# | 1/m | /m | a K0 gradient |
# | deg, - | as they are | friction and dilation angles, ratios |
SHOWN = {"kPa": ("MPa", 1e-3), "kPa/m": ("MPa/m", 1e-3), "rad": ("mrad", 1e3), "1/m": ("/m", 1.0)}
MILLIMETRES = ("A", "B", "D")  # stems of the integration constants that are lengths
STRESSES = ("c", "tension")  # kPa quantities that are strengths, not moduli: shown in kPa


def display(name: str, unit: str) -> tuple[str, float]:
    """(unit shown, factor from the SI value) of parameter `name` whose unit is `unit`."""
    stem = name.split("[")[0]
    if unit == "m" and stem in MILLIMETRES:
        return "mm", 1e3
    if unit == "kPa" and stem in STRESSES:
        return unit, 1.0
    return SHOWN.get(unit, (unit, 1.0))


def _num_text(v: float, digits: int) -> str:
    if not math.isfinite(v):
        return "nan" if math.isnan(v) else ("∞" if v > 0 else "-∞")
    return f"{v:.{digits}g}"


def _suffix(unit: str) -> str:
    return "" if unit in ("-", "") else f" {unit}"


def value_text(name: str, unit: str, value: float, digits: int = 4) -> str:
    """'25.18 MPa', '0.515 mrad', '4.1 mm', '1.6'."""
    u, f = display(name, unit)
    return _num_text(value * f, digits) + _suffix(u)


def pm_text(name: str, unit: str, value: float, std: float) -> str:
    """'25.18 ± 1 MPa'."""
    u, f = display(name, unit)
    return f"{_num_text(value * f, 4)} ± {_num_text(std * f, 2)}{_suffix(u)}"


def interval_text(name: str, unit: str, low: float, high: float) -> str:
    """'[23.14, 27.39] MPa'."""
    u, f = display(name, unit)
    return f"[{_num_text(low * f, 4)}, {_num_text(high * f, 4)}]{_suffix(u)}"


def size_text(name: str, unit: str, size: float) -> str:
    """A detectable size: '±0.26 mrad', '±0.14 MPa/m'."""
    u, f = display(name, unit)
    return f"±{_num_text(size * f, 2)}{_suffix(u)}"
