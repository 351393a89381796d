"""What the case says about time and action: stage dates, instruments installed after a stage, and
trigger levels (TARP: amber and red on a quantity's magnitude), checked and put in SI units.

A trigger level is a number in the quantity's SI unit (m for displacements, kN for a load cell or a
prop's force, kN/m for a thrust or a force per metre run, kNm/m for a moment) or a number with its
unit ('15 mm', '1.2 MN'); a unit of another kind of quantity (a slope in rad on an inclinometer,
whose readings are integrated to displacements; kN on a displacement) is refused.
"""
from __future__ import annotations

from geoback.case.dates import shown_date
from geoback.case.schema import Case

UNITS = {  # kind of quantity -> {unit (lower case): factor to SI}
    "displacement": {"m": 1.0, "mm": 1e-3, "cm": 1e-2},
    "force": {"kn": 1.0, "mn": 1e3},
    "line force": {"kn/m": 1.0, "mn/m": 1e3},
    "moment": {"knm/m": 1.0, "mnm/m": 1e3, "kn.m/m": 1.0},
}
SI = {"displacement": "m", "force": "kN", "line force": "kN/m", "moment": "kNm/m"}


def instrument_quantity(ins) -> str:
    """The kind of quantity an instrument's readings are compared with its levels in."""
    return "force" if ins.kind == "load_cell" else "displacement"


def forecast_quantity(case: Case, f) -> str | None:
    """The kind of quantity of a forecast (None: several quantities, no single level applies)."""
    if f.kind in ("points", "line", "instrument", "convergence"):
        if f.kind == "instrument":
            ins = next((i for i in case.instruments if i.name == f.instrument), None)
            return instrument_quantity(ins) if ins is not None else "displacement"
        return "displacement"
    if f.kind == "support":
        con = case.construction
        sup = next((s for s in (con.props or []) + (con.anchors or []) if s.name == f.support), None) if con else None
        return "force" if sup is not None and getattr(sup, "spacing", None) else "line force"
    if f.kind in ("lining", "wall"):
        if len(f.quantities) != 1:
            return None
        q = f.quantities[0]
        return {"N": "line force", "V": "line force", "M": "moment", "ux": "displacement"}[q]
    return None


def level_si(value, quantity: str) -> float:
    """A level in SI units; ValueError saying what was expected."""
    if isinstance(value, tuple):
        number, unit = value
        factor = UNITS[quantity].get(unit.lower())
        if factor is None:
            allowed = ", ".join(sorted({u.replace("kn", "kN").replace("mn", "MN") for u in UNITS[quantity]}))
            raise ValueError(f"expected a {quantity} ({allowed}), found '{number:g} {unit}'")
        value = number * factor
    if value <= 0:
        raise ValueError(f"expected a positive level (on the magnitude), found {value:g}")
    return float(value)


def levels(triggers, quantity: str) -> tuple[float | None, float | None]:
    """(amber, red) in SI units (None where not given)."""
    if triggers is None:
        return None, None
    return tuple(None if v is None else level_si(v, quantity) for v in (triggers.amber, triggers.red))


def _trigger_problems(at: tuple, triggers, quantity: str | None, what: str) -> list[tuple[tuple, str]]:
    if triggers is None:
        return []
    if triggers.amber is None and triggers.red is None:
        return [(at, "expected an amber or a red level (or both), found neither")]
    if quantity is None:
        return [(at, f"expected trigger levels on a forecast of one quantity, found {what} (split it into one "
                     f"forecast per quantity)")]
    out, got = [], {}
    for level in ("amber", "red"):
        v = getattr(triggers, level)
        if v is None:
            continue
        try:
            got[level] = level_si(v, quantity)
        except ValueError as exc:
            out.append((at + (level,), f"{what}: {exc} ({SI[quantity]} if no unit is written)"))
    if len(got) == 2 and got["red"] <= got["amber"]:
        out.append((at + ("red",), f"expected the red level above the amber level, found red {triggers.red} and "
                                   f"amber {triggers.amber}"))
    return out


def timeline_problems(case: Case) -> list[tuple[tuple, str]]:
    """Stage dates (all or none, in order), installation stages that exist, and trigger levels in a unit
    of their quantity."""
    out: list[tuple[tuple, str]] = []
    con = case.construction
    stages = [s.name for s in con.stages] if con is not None else []
    if con is not None:
        dated = [s.date is not None for s in con.stages]
        if any(dated) and not all(dated):
            k = dated.index(False)
            out.append((("construction", "stages", k, "date"),
                        f"expected a date on every stage once one has a date (placing surveys needs them all), "
                        f"found none on stage '{stages[k]}'"))
        elif all(dated):
            prev = None
            for k, s in enumerate(con.stages):
                start, end = s.date if isinstance(s.date, tuple) else (s.date, None)
                if prev is not None and start <= prev[1]:
                    out.append((("construction", "stages", k, "date"),
                                f"expected stage '{s.name}' to begin after stage '{prev[0]}' "
                                f"{'ended' if prev[2] else 'began'} ({shown_date(prev[1])}), found {shown_date(start)}"))
                prev = (s.name, end if end is not None else start, end is not None)
    for i, ins in enumerate(case.instruments):
        at = ("instruments", i)
        if ins.installed_after is not None and ins.installed_after not in (stages or ["excavation"]):
            out.append((at + ("installed_after",), f"expected one of the construction stages "
                                                   f"({', '.join(stages or ['excavation'])}), found "
                                                   f"'{ins.installed_after}'"))
        if ins.kind == "load_cell" and ins.installed_after is not None:
            out.append((at + ("installed_after",), "expected no installed_after on a load cell: it reads its prop's "
                                                   "or anchor's force since that is installed (its zero: zero:)"))
        if ins.baseline is not None and ins.readings_file is None:
            out.append((at + ("baseline",), "expected a readings_file holding the baseline survey, found inline "
                                             "readings (give inline readings as increments, with installed_after)"))
        out.extend(_trigger_problems(at + ("triggers",), ins.triggers, instrument_quantity(ins),
                                     f"instrument '{ins.name}'"))
    for i, f in enumerate(case.forecasts):
        out.extend(_trigger_problems(("forecasts", i, "triggers"), f.triggers, forecast_quantity(case, f),
                                     f"forecast '{f.name}'" + (f" of {', '.join(f.quantities)}"
                                                               if hasattr(f, "quantities") else "")))
    return out
