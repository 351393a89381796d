"""Forecasts as files and words: forecast.csv, the report's section, summary.json's entry and the
warnings (readers only: everything comes from a ``forecast.Forecasts``)."""
from __future__ import annotations

import numpy as np

from geoback.inference.caveats import Caveat

HEADER = ["forecast", "kind", "stage", "quantity", "unit", "x", "y", "position", "position_is", "value", "std",
          "low95", "high95", "sampled_low95", "sampled_high95", "alert", "p_exceed", "sampled_p_exceed"]
SHOW = {"m": (1e3, "mm"), "kN/m": (1.0, "kN/m"), "kNm/m": (1.0, "kNm/m"), "kN": (1.0, "kN")}
WHAT = {"ux": "horizontal displacement", "uy": "vertical displacement (up +)", "chord": "chord length change",
        "along": "displacement along the line", "normal": "displacement normal to the line", "N": "thrust",
        "M": "bending moment", "V": "shear force"}


def quantity_words(fc, i: int) -> str:
    """What row i of the forecasts is, in words: a lining's N is its thrust, a prop's or anchor's (a
    support forecast, a load cell's reading) its axial force; a wall's ux its deflection."""
    q, kind = fc.quantity[i], fc.kind[i]
    if q == "N" and kind != "lining":
        return "axial force"
    if q == "ux" and kind == "wall":
        return "wall deflection (+ towards larger x)"
    return WHAT.get(q, q)


def positions(fc, rows) -> tuple[np.ndarray, str]:
    """Where each row of a forecast is, as forecast.csv, the report and the figure give it: depth below
    the surface along a vertical line or column of points (a vertical extensometer too, which the
    forecast counts from its reference end), otherwise the forecast's own position."""
    rows = np.asarray(rows)
    x, y = fc.x[rows], fc.y[rows]
    label = fc.position_label[rows[0]]
    if len(rows) > 1 and not label.startswith("angle"):
        span = max(float(np.ptp(x)), float(np.ptp(y)), 1e-12)
        if np.ptp(x) <= 1e-9 * span and np.ptp(y) > 0:
            return -y, "depth [m]"
    return fc.position[rows], label


def _positions_by_row(fc) -> tuple[np.ndarray, list[str]]:
    pos, label = np.array(fc.position, float), list(fc.position_label)
    for name in fc.names:
        rows = fc.rows(name)
        p, lab = positions(fc, rows)
        pos[rows] = p
        for i in rows:
            label[i] = lab
    return pos, label


def forecast_rows(fc) -> list[list]:
    nan = np.full(len(fc.value), np.nan)
    position, position_label = _positions_by_row(fc)
    slo = fc.sampled_low if fc.sampled_low is not None else nan
    shi = fc.sampled_high if fc.sampled_high is not None else nan
    sex = fc.sampled_exceed if fc.sampled_exceed is not None else nan
    return [[fc.forecast[i], fc.kind[i], fc.stage[i], fc.quantity[i], fc.unit[i], fc.x[i], fc.y[i], position[i],
             position_label[i], fc.value[i], fc.std[i], fc.low[i], fc.high[i], slo[i], shi[i], fc.alert[i],
             fc.p_exceed[i], sex[i]] for i in range(len(fc.value))]


def _show(v: float, unit: str) -> str:
    from geoback.units import number

    f, u = SHOW.get(unit, (1.0, unit))
    return f"{number(float(v * f), 3)} {u}"


def _where(fc, i: int) -> str:
    rows = fc.rows(fc.forecast[i])
    pos, label = positions(fc, rows)
    at = float(pos[int(np.flatnonzero(rows == i)[0])])
    if label.startswith("offset"):
        return f"at {at:.3g} m from the {'symmetry' if 'symmetry' in label else 'tunnel'} axis"
    if label.startswith("x,"):
        return f"at x = {at:.3g} m"
    if label.startswith("distance along"):
        return f"at {at:.3g} m along the line ({fc.x[i]:.3g}, {fc.y[i]:.3g})"
    if label.startswith("angle"):
        return f"at {at:.0f}° from the crown"
    if label.startswith("depth"):
        return f"at {at:.3g} m depth"
    if label.startswith("distance"):
        return f"at {at:.3g} m from the reference end"
    return f"at ({fc.x[i]:.3g}, {fc.y[i]:.3g})"


def _percent(p: float) -> str:
    from geoback.units import number

    return number(float(100 * p), 2) if np.isfinite(p) else "n/a"


def summary_lines(fc) -> list[str]:
    """One line per forecast and quantity: the largest magnitude with its band, the alert's chance."""
    out = []
    for name in fc.names:
        rows = fc.rows(name)
        for q in dict.fromkeys(fc.quantity[i] for i in rows):
            sel = [i for i in rows if fc.quantity[i] == q]
            i = max(sel, key=lambda k: abs(fc.value[k]))
            u = fc.unit[i]
            text = (f"- **{name}** ({quantity_words(fc, i)}, stage {fc.stage[i]}): "
                    + (f"largest magnitude {_show(fc.value[i], u)} {_where(fc, i)}" if len(sel) > 1
                       else f"{_show(fc.value[i], u)}")
                    + f" ± {_show(fc.std[i], u)} (95 % [{_show(fc.low[i], u)}, {_show(fc.high[i], u)}]")
            if fc.sampled_low is not None:
                text += f"; sampled [{_show(fc.sampled_low[i], u)}, {_show(fc.sampled_high[i], u)}]"
            text += ")"
            alerts = [k for k in sel if np.isfinite(fc.alert[k])]
            if alerts:
                k = max(alerts, key=lambda j: fc.p_exceed[j])
                p = fc.p_exceed[k]
                text += (f"; probability that |{q}| exceeds the alert level {_show(fc.alert[k], u)}: "
                         f"{_percent(p)} %" + (f" (sampled {_percent(fc.sampled_exceed[k])} %)"
                                               if fc.sampled_exceed is not None else "")
                         + (f" {_where(fc, k)}" if len(sel) > 1 else ""))
            out.append(text)
    return out


def report_section(fc) -> str:
    if fc is None:
        return ""
    lines = ["", "## Forecasts", "",
             f"At the estimate, with the first-order 95 % band from C_p (± {fc.z:.3g} std); the model's "
             "movement, not a future reading (which adds its instrument's error). Quantities not identified "
             "are taken as exact.", ""]
    lines += summary_lines(fc)
    if fc.draws:
        lines += ["", f"Sampling check: {fc.draws} parameter sets drawn from N(p, C_p)"
                      + (f" ({fc.rejected} outside the allowed ranges or failed, left out)" if fc.rejected else "")
                      + " and run through the model: "
                      + ("the sampled 95 % range agrees with the linearised band within 10 %."
                         if not fc.nonlinear else
                         f"it differs from the linearised band by more than 10 % for {', '.join(fc.nonlinear)}: the "
                         "model is non-linear over the parameters' uncertainty, so neither range is exact there; "
                         "the wider of the two is the safer basis for a decision.")]
    top = _leading_parameter(fc)
    if top:
        lines += ["", top]
    lines += ["", "Every point: forecast.csv."]
    return "\n".join(lines) + "\n"


def _leading_parameter(fc) -> str:
    """Which parameter's uncertainty matters most for each forecast (where its std is largest)."""
    if not fc.parameters:
        return ""
    share = fc.contributions()
    parts = []
    for name in fc.names:
        rows = fc.rows(name)
        i = rows[np.argmax(fc.std[rows])]
        j = int(np.argmax(share[i]))
        if share[i, j] > 0:
            parts.append(f"{name}: {fc.parameters[j]} ({100 * share[i, j]:.0f} %)")
    return ("Knowing one parameter exactly would narrow each forecast most for: " + ", ".join(parts)
            + " (the share of its variance removed, correlations included).") if parts else ""


def as_dict(fc) -> dict:
    out = {"z": fc.z, "draws": fc.draws, "rejected": fc.rejected, "nonlinear": fc.nonlinear,
           "counts": {k: fc.counts.get(k, 0) for k in ("factorisations", "solves", "forward_runs")},
           "seconds": round(fc.seconds, 4), "forecasts": {}}
    for name in fc.names:
        rows = fc.rows(name)
        out["forecasts"][name] = {
            "kind": fc.kind[rows[0]], "stage": fc.stage[rows[0]],
            "rows": [dict(zip(HEADER[3:], [_plain(v) for v in r[3:]])) for r in
                     (forecast_rows(fc)[i] for i in rows)]}
    return out


def _plain(v):
    if isinstance(v, (np.floating, float)):
        return None if not np.isfinite(v) else float(v)
    return v


def forecast_caveats(fc) -> list[Caveat]:
    if fc is None or not fc.nonlinear:
        return []
    return [Caveat("forecast-nonlinear",
                   f"the linearised 95 % band of {', '.join(fc.nonlinear)} differs by more than 10 % from the range "
                   "of the model's forecasts at parameter sets drawn from N(p, C_p): the model is non-linear over "
                   "the parameters' uncertainty, so neither range is exact; base decisions on the wider one "
                   "(forecast.csv: low95/high95 and sampled_low95/sampled_high95) or narrow the uncertainty "
                   "(more readings, a prior)")]
