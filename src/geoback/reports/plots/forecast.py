"""One figure per forecast: the forecast at the estimate with its 95 % band (linearised, and the
range sampled through the model), the alert level, along the line, the instrument or the lining;
with the readings taken so far where the forecast is of something the instruments read (an
instrument at a later stage, a line through settlement points)."""
from __future__ import annotations

import numpy as np

from geoback.reports.plots.common import Figure, new_figure
from geoback.reports.forecast_report import SHOW, positions, quantity_words

BAND = "#1f77b4"
SAMPLED = "#555555"
ALERT = "#d62728"
READ_COLOURS = ("#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#ff7f0e")
DEPTH = "depth below the surface [m]"


def _scale(unit: str) -> tuple[float, str]:
    return SHOW.get(unit, (1.0, unit))


def layout(fc, rows) -> tuple[np.ndarray, str, bool]:
    """(position of each row, its axis label, vertical): a vertical line or column of points against
    depth, a horizontal one against x (the offset from the tunnel axis), otherwise as the forecast
    says (distance along the line, angle, reading number)."""
    pos, label = positions(fc, rows)
    if label.startswith("depth"):
        return pos, DEPTH, True
    x, y = fc.x[rows], fc.y[rows]
    if len(rows) > 1 and not label.startswith("angle") and np.ptp(y) <= 1e-9 * max(np.ptp(x), 1e-12) < np.ptp(x):
        return x, label if label.startswith(("offset", "x,")) else "horizontal distance from the symmetry axis x [m]", False
    return pos, label, False


def _profile(ax, fc, rows, pos, label, vertical: bool) -> None:
    """Value and bands along a position (depth downwards when `vertical`)."""
    f, unit = _scale(fc.unit[rows[0]])
    order = np.argsort(pos)
    r, pos = rows[order], pos[order]
    val, lo, hi = f * fc.value[r], f * fc.low[r], f * fc.high[r]
    fill = ax.fill_betweenx if vertical else ax.fill_between
    plot = (lambda a, b, **k: ax.plot(b, a, **k)) if vertical else (lambda a, b, **k: ax.plot(a, b, **k))
    fill(pos, lo, hi, color=BAND, alpha=0.25, lw=0, label="95 % band (linearised)")
    plot(pos, val, color=BAND, lw=1.8, label="forecast at the estimate")
    if fc.sampled_low is not None:
        plot(pos, f * fc.sampled_low[r], color=SAMPLED, lw=1.0, ls="--", label=f"95 % range, {fc.draws} draws")
        plot(pos, f * fc.sampled_high[r], color=SAMPLED, lw=1.0, ls="--")
    alert = fc.alert[r[0]]
    if np.isfinite(alert):
        line = ax.axvline if vertical else ax.axhline
        drawn = [s for s in (-1, 1) if (s < 0 and lo.min() < 0) or (s > 0 and hi.max() > 0)]
        for s in drawn:  # one legend entry for the pair
            line(s * f * alert, color=ALERT, lw=1.0, ls=":",
                 label=("alert level (±)" if len(drawn) == 2 else "alert level") if s == drawn[0] else None)
    what = f"{quantity_words(fc, r[0])} [{unit}]"
    if vertical:
        ax.set_xlabel(what)
        ax.set_ylabel(label)
        ax.invert_yaxis()
    else:
        ax.set_xlabel(label)
        ax.set_ylabel(what)
    ax.axhline(0, color="0.6", lw=0.6) if not vertical else ax.axvline(0, color="0.6", lw=0.6)


def _points(ax, fc, rows) -> None:
    f, unit = _scale(fc.unit[rows[0]])
    k = np.arange(len(rows))
    labels = [f"({fc.x[i]:.3g}, {fc.y[i]:.3g}) {fc.quantity[i]}" for i in rows]
    val = f * fc.value[rows]
    ax.errorbar(k, val, yerr=[val - f * fc.low[rows], f * fc.high[rows] - val], fmt="o", color=BAND, capsize=4,
                label="forecast, 95 % band")
    if fc.sampled_low is not None:
        ax.errorbar(k + 0.15, val, yerr=[val - f * fc.sampled_low[rows], f * fc.sampled_high[rows] - val], fmt="none",
                    color=SAMPLED, capsize=3, ls="--", label=f"95 % range, {fc.draws} draws")
    ax.set_xticks(k, labels, rotation=20 if len(k) > 3 else 0)
    ax.set_xlabel("reading: point (x, y) [m] and component")
    ax.set_ylabel(f"forecast [{unit}]")
    ax.axhline(0, color="0.6", lw=0.6)


def _spread_points(ax, fc, rows, pos, label, vertical: bool) -> None:
    """Points in a row or column: each forecast with its 95 % error bar at its real position."""
    f, unit = _scale(fc.unit[rows[0]])
    val = f * fc.value[rows]
    pair = (lambda p, v: (v, p)) if vertical else (lambda p, v: (p, v))
    err = [val - f * fc.low[rows], f * fc.high[rows] - val]
    ax.errorbar(*pair(pos, val), **({"xerr": err} if vertical else {"yerr": err}), fmt="o", color=BAND, capsize=4,
                label="forecast, 95 % band")
    if fc.sampled_low is not None:
        err = [val - f * fc.sampled_low[rows], f * fc.sampled_high[rows] - val]
        ax.errorbar(*pair(pos, val), **({"xerr": err} if vertical else {"yerr": err}), fmt="none", color=SAMPLED,
                    capsize=3, ls="--", label=f"95 % range, {fc.draws} draws")
    what = f"{quantity_words(fc, rows[0])} [{unit}]"
    if vertical:
        ax.set_xlabel(what)
        ax.set_ylabel(label)
        ax.invert_yaxis()
        ax.axvline(0, color="0.6", lw=0.6)
    else:
        ax.set_xlabel(label)
        ax.set_ylabel(what)
        ax.axhline(0, color="0.6", lw=0.6)


def readings_so_far(res, fc, name: str) -> list[tuple[str, str, np.ndarray, np.ndarray, np.ndarray]]:
    """The readings behind a forecast: (instrument, stage, x, y, measured, sigma) of every stage an
    instrument was read at before the forecast's stage, where the forecast is of that instrument
    (kind 'instrument') or runs along a line through its points (the same component)."""
    if res is None or getattr(res, "data", None) is None:
        return []
    rows = fc.rows(name)
    kind, stage = fc.kind[rows[0]], fc.stage[rows[0]]
    spec = next((f for f in (res.case.forecasts or []) if f.name == name), None)
    sigma = np.sqrt(np.clip(np.diag(res.data.covariance), 0, None))
    out = []
    for block, sl in res.data.block_rows():
        if block.stage == stage:
            continue
        labs = block.labels
        xy = np.array([[lab.x, lab.y] for lab in labs])
        keep = None
        if kind == "instrument" and spec is not None and getattr(spec, "instrument", None) == block.name:
            keep = np.ones(len(labs), bool)
        elif kind == "line" and block.kind == "points":
            a = np.array([fc.x[rows[0]], fc.y[rows[0]]])
            b = np.array([fc.x[rows[-1]], fc.y[rows[-1]]])
            d = b - a
            t = np.clip((xy - a) @ d / max(d @ d, 1e-300), 0.0, 1.0)
            off = np.hypot(*(xy - (a + t[:, None] * d)).T)
            keep = (off <= 1e-6 * max(np.sqrt(d @ d), 1.0)) & np.array([lab.component == fc.quantity[rows[0]]
                                                                        for lab in labs])
        if keep is None or not keep.any():
            continue
        idx = np.arange(sl.start, sl.stop)[keep]
        out.append((block.name, block.stage, xy[keep, 0], xy[keep, 1], res.data.measured[idx], sigma[idx]))
    return out


def _readings(ax, fc, rows, read, vertical: bool, label: str) -> None:
    """The readings so far with ±2σ, at the forecast's positions (depth, x or distance along)."""
    f, _ = _scale(fc.unit[rows[0]])
    for k, (inst, stage, x, y, meas, sg) in enumerate(read):
        if label == DEPTH or label.startswith("depth"):
            pos = -y
        elif label.startswith(("offset", "horizontal")):
            pos = x
        else:  # distance from the forecast's first row (along the line or from the reference end)
            near = [int(np.argmin(np.hypot(fc.x[rows] - xi, fc.y[rows] - yi))) for xi, yi in zip(x, y)]
            pos = fc.position[rows][near]
        c = READ_COLOURS[k % len(READ_COLOURS)]
        err = 2 * f * sg
        kw = {"xerr": err} if vertical else {"yerr": err}
        v = f * meas
        ax.errorbar(*((v, pos) if vertical else (pos, v)), **kw, ls="none", marker="x", ms=7, mew=1.8, color=c,
                    capsize=3, elinewidth=1.0, zorder=5, label=f"{inst} read after stage '{stage}' (± 2σ)")


def _is_force(fc, rows) -> bool:
    """A prop's or anchor's axial force: a support forecast, or a load cell's reading."""
    return fc.quantity[rows[0]] == "N" and fc.kind[rows[0]] in ("support", "instrument")


def force_readings(res, fc, name: str) -> list[tuple[str, str, float, float]]:
    """The load-cell readings of the support a force forecast is of, at the stages before it: (load cell,
    stage, reading, sigma), in the forecast's unit (the load cell's)."""
    if res is None or getattr(res, "data", None) is None:
        return []
    rows = fc.rows(name)
    spec = next((f for f in (res.case.forecasts or []) if f.name == name), None)
    cells = {ins.name: ins.support for ins in res.case.instruments if ins.kind == "load_cell"}
    if spec is None:
        return []
    support = getattr(spec, "support", None) or cells.get(getattr(spec, "instrument", None))
    sigma = np.sqrt(np.clip(np.diag(res.data.covariance), 0, None))
    out = []
    for block, sl in res.data.block_rows():
        if block.stage == fc.stage[rows[0]] or cells.get(block.name) != support:
            continue
        for i in range(sl.start, sl.stop):
            out.append((block.name, block.stage, float(res.data.measured[i]), float(sigma[i])))
    return out


def _by_stage(ax, fc, rows, read, stages) -> None:
    """A force against the construction stages: the forecast at its stage with its bands, the load-cell
    readings so far at theirs (± 2σ)."""
    f, unit = _scale(fc.unit[rows[0]])
    order = list(stages)
    i = rows[0]
    k = order.index(fc.stage[i]) if fc.stage[i] in order else len(order) - 1
    v = f * fc.value[i]
    ax.errorbar([k], [v], yerr=[[v - f * fc.low[i]], [f * fc.high[i] - v]], fmt="o", ms=7, color=BAND, capsize=5,
                label="forecast, 95 % band")
    if fc.sampled_low is not None:
        ax.errorbar([k + 0.08], [v], yerr=[[v - f * fc.sampled_low[i]], [f * fc.sampled_high[i] - v]], fmt="none",
                    color=SAMPLED, capsize=3, ls="--", label=f"95 % range, {fc.draws} draws")
    cells = list(dict.fromkeys(r[0] for r in read))
    for inst, stage, meas, sg in read:
        c = READ_COLOURS[cells.index(inst) % len(READ_COLOURS)]
        first = not any(line.get_label().startswith(inst) for line in ax.lines)
        ax.errorbar([order.index(stage)], [f * meas], yerr=[2 * f * sg], fmt="x", ms=7, mew=1.8, color=c, capsize=3,
                    label=f"{inst} readings so far (± 2σ)" if first else None)
    alert = fc.alert[i]
    if np.isfinite(alert):
        ax.axhline(f * alert, color=ALERT, lw=1.0, ls=":", label="alert level")
    ax.set_xticks(range(len(order)), [f"after '{st}'" for st in order], rotation=20 if len(order) > 4 else 0)
    ax.set_xlim(-0.5, len(order) - 0.5)
    ax.set_xlabel("construction stage")
    per = "per prop or anchor" if unit == "kN" else "per metre run of wall"
    ax.set_ylabel(f"{quantity_words(fc, i)} {per} [{unit}]")
    ax.axhline(0, color="0.6", lw=0.6)


def forecast_figure(fc, name: str, res=None) -> Figure:
    """The forecast `name` with its bands; `res`: the identification it comes from, whose readings so
    far are drawn with it where they are of the same thing (None: the forecast alone)."""
    rows = fc.rows(name)
    kind, stage = fc.kind[rows[0]], fc.stage[rows[0]]
    quantities = list(dict.fromkeys(fc.quantity[i] for i in rows))
    if kind == "lining":
        fig = Figure(figsize=(6.4, 2.6 * len(quantities)))
        axes = fig.subplots(len(quantities), 1, sharex=True, squeeze=False)[:, 0]
        for ax, q in zip(axes, quantities):
            r = np.array([i for i in rows if fc.quantity[i] == q])
            _profile(ax, fc, r, fc.position[r], fc.position_label[r[0]], vertical=False)
        axes[-1].set_xlabel("angle from the crown [°]")
        for ax in axes[:-1]:
            ax.set_xlabel("")
        read = []
    elif kind == "wall":  # against depth, one panel per quantity
        fig = new_figure(3.6 * len(quantities) + 0.8, 6.4)
        axes = fig.subplots(1, len(quantities), sharey=True, squeeze=False)[0]
        for ax, q in zip(axes, quantities):
            r = np.array([i for i in rows if fc.quantity[i] == q])
            _profile(ax, fc, r, -fc.y[r], DEPTH, vertical=True)
        for ax in axes[1:]:
            ax.set_ylabel("")
        read, vertical = [], True
    elif _is_force(fc, rows):
        fig = Figure(figsize=(6.4, 3.8), layout="constrained")
        ax = fig.subplots()
        read = force_readings(res, fc, name)
        from geoback.reports.section import stage_names

        stages = stage_names(res.case) if res is not None else [fc.stage[rows[0]]]
        _by_stage(ax, fc, rows, read, stages)
        axes, vertical = [ax], False
    else:
        pos, label, vertical = layout(fc, rows)
        fig = new_figure(5.2, 6.4) if vertical else Figure(figsize=(6.4, 3.8))
        ax = fig.subplots()
        spread = label == DEPTH or label.startswith(("offset", "horizontal"))
        if kind == "convergence" or (kind == "points" and not spread):
            _points(ax, fc, rows)
            read = []
        elif kind == "points" or (kind == "instrument" and fc.position_label[rows[0]] == "reading"):
            _spread_points(ax, fc, rows, pos, label, vertical)
            read = readings_so_far(res, fc, name)
        else:
            _profile(ax, fc, rows, pos, label, vertical)
            read = readings_so_far(res, fc, name)
        if read:
            _readings(ax, fc, rows, read, vertical, label)
        axes = [ax]
    if kind == "wall":
        handles, labels = axes[0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="outside lower center", frameon=False, fontsize=8, ncols=2)
    elif kind != "lining" and vertical:  # below the panel: a profile fills its frame
        fig.legend(*axes[0].get_legend_handles_labels(), loc="outside lower center", frameon=False, fontsize=8,
                   ncols=2)
    else:
        axes[0].legend(loc="best", frameon=False, fontsize=8)
    sub = ("\nwith the readings so far" if read else "")
    what = ""
    if kind == "wall":
        what = f": wall '{_spec_field(res, name, 'wall')}'" if res is not None else ""
    elif kind == "support":
        what = f": axial force of '{_spec_field(res, name, 'support')}'" if res is not None else ""
    fig.suptitle(f"Forecast '{name}'{what} after stage '{stage}' with its 95 % band{sub}")
    return fig


def forecast_figures(fc, res=None) -> dict:
    """{'forecast_<name>': Figure} for every forecast (with the readings so far from `res`)."""
    return {f"forecast_{name}": forecast_figure(fc, name, res) for name in fc.names}


def _spec_field(res, name: str, field: str) -> str:
    spec = next((f for f in (res.case.forecasts or []) if f.name == name), None)
    return str(getattr(spec, field, "")) if spec is not None else ""
