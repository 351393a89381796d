"""How `diagnose` shows a quantity to people: one engineering unit per kind of quantity, the same
for a value, its std, its interval and a detectable size, everywhere in diagnosis.md.

| SI unit (the case's) | shown in | for |
|---|---|---|
| kPa | MPa | every modulus, the ground's and the lining's alike (a shotcrete 30 GPa is 30000 MPa) |
| kPa | kPa | a strength: cohesion c', tension cut-off |
| kPa/m | MPa/m | a modulus gradient |
| rad | mrad | an inclinometer's bias shift, a deflectometer's end rotation (never mm/m beside rad) |
| m | mm | an instrument's reference-end movement (A, B, D) |
| m | m | a depth offset, a boundary depth |
| 1/m | /m | a K0 gradient |
| deg, - | as they are | friction and dilation angles, ratios |
"""
from __future__ import annotations

import math

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


def _num(v: float, digits: int) -> str:
    if not math.isfinite(v):
        return "nan" if math.isnan(v) else ("∞" if v > 0 else "-∞")
    return f"{v:.{digits}g}"


def _suffix(unit: str) -> str:
    return "" if unit in ("-", "") else f" {unit}"


def shown(name: str, unit: str, value: float, digits: int = 4) -> str:
    """'25.18 MPa', '0.515 mrad', '4.1 mm', '1.6'."""
    u, f = display(name, unit)
    return _num(value * f, digits) + _suffix(u)


def shown_pm(name: str, unit: str, value: float, std: float) -> str:
    """'25.18 ± 1 MPa'."""
    u, f = display(name, unit)
    return f"{_num(value * f, 4)} ± {_num(std * f, 2)}{_suffix(u)}"


def shown_interval(name: str, unit: str, low: float, high: float) -> str:
    """'[23.14, 27.39] MPa'."""
    u, f = display(name, unit)
    return f"[{_num(low * f, 4)}, {_num(high * f, 4)}]{_suffix(u)}"


def shown_size(name: str, unit: str, size: float) -> str:
    """A detectable size: '±0.26 mrad', '±0.14 MPa/m'."""
    u, f = display(name, unit)
    return f"±{_num(size * f, 2)}{_suffix(u)}"
