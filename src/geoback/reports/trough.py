"""The settlement trough and the building damage as files and words: trough.csv, damage.csv, the
report's sections "Settlement trough" and "Building damage (greenfield)" and summary.json's "trough"
and "damage" (readers only: everything comes from a ``worth.trough.Troughs`` and a
``worth.damage.Damage``).

trough.csv: per stage and source (measured: the readings' fit, weighted by C_x; model: the fit of the
model's surface settlement at the estimate, band from C_p) S_max [mm], i [m], K [-], V_L [%], x0 [m],
V_s [m3/m] with std and 95 % band, z0 and the excavated area it is read against, and why a fit is
not determined (its numbers then left empty). damage.csv: per building, stage and sagging or hogging
part Delta/L, eps_h, eps_b, eps_d, eps_br, eps_dr [%], the critical strain and category; a row per
building and stage ('whole') with its category and the probability of each.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from geoback.outputs import write_csv
from geoback.units import rounded

SOURCE = {"measured": "measured", "predicted": "model"}
TROUGH_QUANTITIES = (("S_max", "S_max [mm]", 1e3), ("i", "i [m]", 1.0), ("K", "K [-]", 1.0),
                     ("V_L", "V_L [%]", 1.0), ("x0", "x0 [m]", 1.0), ("V_s", "V_s [m3/m]", 1.0))
TROUGH_HEADER = (["stage", "source", "determined"]
                 + [h for _, u, _ in TROUGH_QUANTITIES for h in (u, u.replace(" [", "_std ["), u.replace(" [", "_low95 ["),
                                                                  u.replace(" [", "_high95 ["))]
                 + ["x0 set by", "z0 [m]", "excavated area [m2]", "half model", "points", "chi2", "dof",
                    "instruments", "note"])


def _cell(v):
    return "" if v is None or not np.isfinite(v) else rounded(float(v))


def _z(tr, t) -> float:
    return t.z_measured if tr.source == "measured" else t.z


def _troughs(t):
    for stage in t.stages:
        for src in (t.measured, t.predicted):
            if stage in src:
                yield src[stage]


def trough_rows(t) -> list[list]:
    rows = []
    for tr in _troughs(t):
        z = _z(tr, t)
        row = [tr.stage, SOURCE[tr.source], tr.determined]
        for q, _, f in TROUGH_QUANTITIES:
            v, s = tr.values[q], tr.std[q]
            if not tr.determined:
                row += ["", "", "", ""]
            elif q == "x0" and tr.x0_how != "fitted":
                row += [_cell(f * v), "", "", ""]
            else:
                row += [_cell(f * v), _cell(f * s), _cell(f * (v - z * s)), _cell(f * (v + z * s))]
        row += [tr.x0_how, rounded(tr.z0), rounded(tr.area), tr.half, len(tr.x), rounded(tr.chi2), tr.dof,
                " ".join(tr.instruments), tr.reason]
        rows.append(row)
    return rows


PCT = 100.0
DAMAGE_HEADER = ["building", "stage", "part", "mode", "x_a [m]", "x_b [m]", "L [m]", "deflection [mm]",
                 "deflection ratio [%]", "eps_h [%]", "eps_b [%]", "eps_d [%]", "eps_br [%]", "eps_dr [%]",
                 "critical strain [%]", "category", "critical_low95 [%]", "critical_high95 [%]"] + \
                [f"P(category {c.split()[0]})" for c in
                 ("0 negligible", "1 very slight", "2 slight", "3 moderate", "4-5 severe")]


def damage_rows(dm) -> list[list]:
    from geoback.worth.damage import CATEGORIES

    rows = []
    for b in dm.buildings.values():
        for stage, bs in b.stages.items():
            for k, p in enumerate(bs.parts):
                rows.append([b.name, stage, k + 1, p.mode, rounded(p.x_a), rounded(p.x_b), rounded(p.length),
                             rounded(1e3 * p.deflection), rounded(PCT * p.deflection_ratio), rounded(PCT * p.eps_h),
                             rounded(PCT * p.eps_b), rounded(PCT * p.eps_d), rounded(PCT * p.eps_br),
                             rounded(PCT * p.eps_dr), rounded(PCT * p.critical), CATEGORIES[p.category], "", ""]
                            + [""] * len(CATEGORIES))
            q = bs.strain_quantiles
            probs = [rounded(float(v)) for v in bs.probabilities] if bs.probabilities is not None \
                else [""] * len(CATEGORIES)
            rows.append([b.name, stage, "whole", "", rounded(b.x_start), rounded(b.x_start + b.length),
                         rounded(b.length), "", "", "", "", "", "", "", rounded(PCT * bs.critical),
                         CATEGORIES[bs.category], rounded(PCT * q[0]) if q else "", rounded(PCT * q[2]) if q else ""]
                        + probs)
    return rows


def write_trough(t, out: Path) -> Path:
    path = Path(out) / "trough.csv"
    write_csv(path, TROUGH_HEADER, trough_rows(t))
    return path


def write_damage(dm, out: Path) -> Path:
    path = Path(out) / "damage.csv"
    write_csv(path, DAMAGE_HEADER, damage_rows(dm))
    return path


def _num(v):
    return float(v) if v is not None and np.isfinite(v) else None


def trough_dict(t) -> dict:
    """summary.json's "trough": per stage the measured and model troughs (SI: S_max and i in m, V_L in %)."""
    stages = {}
    for tr in _troughs(t):
        z = _z(tr, t)
        d = {"determined": tr.determined, "reason": tr.reason or None, "x0_set_by": tr.x0_how, "z0_m": tr.z0,
             "excavated_area_m2": tr.area, "half_model": tr.half, "points": len(tr.x), "chi2": tr.chi2, "dof": tr.dof}
        if tr.determined:
            for q in ("S_max", "i", "x0", "V_s", "V_L", "K"):
                v, s = tr.values[q], tr.std[q]
                d[q] = {"value": _num(v), "std": _num(s), "ci95": [_num(v - z * s), _num(v + z * s)]
                        if np.isfinite(s) else None}
        if tr.instruments:
            d["instruments"] = list(tr.instruments)
        stages.setdefault(tr.stage, {})[SOURCE[tr.source]] = d
    return {"z": t.z, "parameters": list(t.parameters), "assumed": list(t.assumed), "stages": stages,
            "units": {"S_max": "m", "i": "m", "x0": "m", "V_s": "m3/m", "V_L": "%", "K": "-"}}


def damage_dict(dm) -> dict:
    """summary.json's "damage": per building and stage the critical strain, category and probabilities."""
    from geoback.worth.damage import CATEGORIES

    out = {}
    for b in dm.buildings.values():
        st = {}
        for stage, bs in b.stages.items():
            st[stage] = {"critical_strain": bs.critical, "category": CATEGORIES[bs.category],
                         "category_index": bs.category,
                         "probabilities": ({c: float(p) for c, p in zip(CATEGORIES, bs.probabilities)}
                                           if bs.probabilities is not None else None),
                         "critical_strain_95": [bs.strain_quantiles[0], bs.strain_quantiles[2]]
                         if bs.strain_quantiles else None,
                         "parts": [{"mode": p.mode, "x_a_m": p.x_a, "x_b_m": p.x_b, "deflection_ratio": p.deflection_ratio,
                                    "eps_h": p.eps_h, "eps_b": p.eps_b, "eps_d": p.eps_d, "eps_br": p.eps_br,
                                    "eps_dr": p.eps_dr, "category": CATEGORIES[p.category]} for p in bs.parts]}
        out[b.name] = {"x_start_m": b.x_start, "length_m": b.length, "height_m": b.height,
                       "foundation_depth_m": b.foundation_depth, "E_over_G": b.E_over_G, "nu": b.nu, "stages": st}
    return {"greenfield": True, "method": dm.method, "draws": dm.draws, "parameters": list(dm.parameters),
            "buildings": out}


def _pm(v, s, z, digits=".3g") -> str:
    if s is None or not np.isfinite(s):
        return f"{v:{digits}}" + (" (± ∞: not determined by the readings)" if s is not None and math.isinf(s) else "")
    return f"{v:{digits}} ± {s:.2g} ([{v - z * s:{digits}}, {v + z * s:{digits}}])"


def trough_section(t) -> str:
    """The report's "Settlement trough"."""
    if t is None or not t:
        return ""
    lines = ["", "## Settlement trough", "",
             "The Gaussian trough S(x) = S_max exp(−(x − x0)² / (2 i²)) (settlement down positive), fitted per "
             "stage to the surface settlements read (weighted least squares with their covariance C_x) and to the "
             f"model's surface settlement at the estimate (95 % band from C_p, first order, ± {t.z:.3g} std, through "
             "the exact sensitivities of the settlement). Volume loss V_L = 100 √(2π) i S_max / A, trough width "
             "parameter K = i / z0. Values ± std (95 % interval).", "", "Assumed:", ""]
    lines += [f"- {a}" for a in t.assumed]
    lines += ["", "| after stage | trough | S_max [mm] | i [m] | K [-] | V_L [%] | x0 [m] | fit |",
              "|---|---|---|---|---|---|---|---|"]
    for tr in _troughs(t):
        z = _z(tr, t)
        who = (f"measured ({', '.join(tr.instruments)}, {len(tr.x)} points)" if tr.source == "measured"
               else "model")
        if not tr.determined:
            lines.append(f"| {tr.stage} | {who} | not determined: {tr.reason} | | | | | |")
            continue
        v, s = tr.values, tr.std
        x0 = (_pm(v["x0"], s["x0"], z) + " (fitted)") if tr.x0_how == "fitted" else f"{v['x0']:g} ({tr.x0_how})"
        fit = (f"χ² = {tr.chi2:.3g} on {tr.dof} dof" if tr.source == "measured" else
               f"rms misfit {1e3 * math.sqrt(tr.chi2 / max(len(tr.x), 1)):.2g} mm")
        lines.append(f"| {tr.stage} | {who} | {_pm(1e3 * v['S_max'], 1e3 * s['S_max'], z)} | "
                     f"{_pm(v['i'], s['i'], z)} | {_pm(v['K'], s['K'], z, '.2f')} | {_pm(v['V_L'], s['V_L'], z)} | "
                     f"{x0} | {fit} |")
    poor = [tr for tr in t.measured.values() if tr.determined and tr.dof > 0 and tr.chi2 > _chi2_99(tr.dof)]
    if poor:
        lines += ["", "The measured settlements of " + ", ".join(f"'{tr.stage}'" for tr in poor)
                  + " depart from a Gaussian trough by more than their σ allows (χ² above its 99 % point): the "
                    "intervals there hold only as far as the Gaussian shape does."]
    lines += ["", "Every stage's troughs with their bands: trough.csv."]
    return "\n".join(lines) + "\n"


def _chi2_99(dof: int) -> float:
    from scipy.special import chdtri  # chi2.ppf(0.99, dof), without importing scipy.stats (0.5 s)

    return float(chdtri(dof, 0.01))


def damage_section(dm) -> str:
    """The report's "Building damage (greenfield)"."""
    from geoback.worth.damage import CATEGORIES

    if dm is None or not dm.buildings:
        return ""
    lines = ["", "## Building damage (greenfield)", "",
             "A greenfield assessment: the ground movement at each building's foundation level is the model's "
             "without the building (its stiffness and weight are not in the model), which usually overstates what "
             "a real building suffers. Each building is split at the inflection points of the settlement profile into "
             "sagging and hogging parts; per part the deflection ratio Δ/L (largest deflection from the chord), the "
             "average horizontal strain ε_h (extension +; compression taken as 0) and the deep beam's limiting "
             "bending and shear strains (Burland & Wroth 1974; neutral axis at mid-height for sagging, at the bottom "
             "for hogging), combined with ε_h (Boscardin & Cording 1989; Burland 1995): ε_br = ε_h + ε_b, "
             "ε_dr = ε_h (1 − ν)/2 + √(ε_h² ((1 + ν)/2)² + ε_d²). Categories by the critical strain: "
             "0 negligible < 0.05 %, 1 very slight 0.05–0.075 %, 2 slight 0.075–0.15 %, 3 moderate 0.15–0.3 %, "
             "4–5 severe to very severe > 0.3 %.", "",
             f"Probabilities of each category: {dm.method}.", "",
             "| building | after stage | part | x [m] | Δ/L [%] | ε_h [%] | ε_b [%] | ε_d [%] | critical ε [%] | "
             "category |", "|---|---|---|---|---|---|---|---|---|---|"]
    for b in dm.buildings.values():
        for stage, bs in b.stages.items():
            for p in bs.parts:
                lines.append(f"| {b.name} | {stage} | {p.mode} | {p.x_a:.1f} to {p.x_b:.1f} | "
                             f"{PCT * p.deflection_ratio:.3g} | {PCT * p.eps_h:.3g} | {PCT * p.eps_b:.3g} | "
                             f"{PCT * p.eps_d:.3g} | {PCT * p.critical:.3g} | {CATEGORIES[p.category]} |")
    lines += ["", "| building | after stage | critical ε [%] (95 % range) | category | "
              + " | ".join(f"P({c})" for c in CATEGORIES) + " |", "|---|---|---|---|" + "---|" * len(CATEGORIES)]
    for b in dm.buildings.values():
        where = (f"{b.name} (x {b.x_start:g} to {b.x_start + b.length:g} m, {b.height:g} m high"
                 + (f", foundation {b.foundation_depth:g} m deep" if b.foundation_depth else "") + ")")
        for stage, bs in b.stages.items():
            q = bs.strain_quantiles
            rng = f" ({PCT * q[0]:.3g} to {PCT * q[2]:.3g})" if q else ""
            probs = [f"{100 * p:.0f} %" if p >= 0.005 or p == 0 else "< 1 %" for p in bs.probabilities] \
                if bs.probabilities is not None else ["–"] * len(CATEGORIES)
            lines.append(f"| {where} | {stage} | {PCT * bs.critical:.3g}{rng} | {CATEGORIES[bs.category]} | "
                         + " | ".join(probs) + " |")
    lines += ["", "Every part and stage: damage.csv."]
    return "\n".join(lines) + "\n"
