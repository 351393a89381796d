"""Walls and supports as files and words: walls.csv, supports.csv and the report's section "Walls and
supports" (readers only: everything comes from a ``worth.walls.WallsAndSupports``).

walls.csv: every wall, stage (from its installation on) and depth: the centreline's horizontal
deflection ux [mm] (+ towards larger x, as the model's x axis), shear V [kN/m] and bending moment M
[kNm/m] (+ the wall's face at larger x in tension), per metre run, each with its std and 95 % band
where parameters are identified. supports.csv: every prop and anchor and stage from its installation
on: its axial force per metre run [kN/m] (prop compression +, anchor tension +) and, where the case
gives a spacing, per prop or anchor [kN], with std and band.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from geoback.outputs import write_csv
from geoback.units import rounded

WALLS_HEADER = ["wall", "stage", "depth [m]", "excavation level [m]", "ux [mm]", "ux_std [mm]", "ux_low95 [mm]",
                "ux_high95 [mm]", "V [kN/m]", "V_std [kN/m]", "V_low95 [kN/m]", "V_high95 [kN/m]", "M [kNm/m]",
                "M_std [kNm/m]", "M_low95 [kNm/m]", "M_high95 [kNm/m]"]
SUPPORTS_HEADER = ["support", "kind", "wall", "depth [m]", "stage", "force per metre run [kN/m]",
                   "force_std [kN/m]", "force_low95 [kN/m]", "force_high95 [kN/m]", "spacing [m]",
                   "force per support [kN]", "force per support_std [kN]", "force per support_low95 [kN]",
                   "force per support_high95 [kN]"]
FORCE_WORD = {"prop": "compression", "anchor": "tension"}


def _cell(v) -> object:
    return "" if v is None or not np.isfinite(v) else rounded(float(v))


def _band(v, s, z, f=1.0) -> list:
    """value, std, low, high (times f); std and band empty without identified parameters."""
    if s is None or not np.isfinite(s):
        return [_cell(f * v), "", "", ""]
    return [_cell(f * v), _cell(f * s), _cell(f * (v - z * s)), _cell(f * (v + z * s))]


def wall_rows(ws) -> list[list]:
    rows = []
    for w in ws.walls.values():
        for k, stage in enumerate(w.stages):
            if not np.isfinite(w.M[k]).any():  # not installed yet
                continue
            for i, d in enumerate(w.depths):
                row = [w.name, stage, round(float(d), 4), rounded(float(w.formation[k]))]
                for q, f in (("ux", 1e3), ("V", 1.0), ("M", 1.0)):
                    s = getattr(w, f"{q}_std")
                    row += _band(getattr(w, q)[k, i], None if s is None else s[k, i], ws.z, f)
                rows.append(row)
    return rows


def support_rows(ws) -> list[list]:
    rows = []
    for s in ws.supports.values():
        for k, stage in enumerate(s.stages):
            if not np.isfinite(s.force[k]):
                continue
            sd = None if s.std is None else s.std[k]
            row = [s.name, s.kind, s.wall, rounded(s.depth), stage] + _band(s.force[k], sd, ws.z)
            if s.spacing is not None:
                row += [rounded(s.spacing)] + _band(s.force[k], sd, ws.z, s.spacing)
            else:
                row += ["", "", "", "", ""]
            rows.append(row)
    return rows


def write_walls(ws, out: Path) -> list[Path]:
    """walls.csv and supports.csv (module docstring) into `out`."""
    out = Path(out)
    paths = [out / "walls.csv", out / "supports.csv"]
    write_csv(paths[0], WALLS_HEADER, wall_rows(ws))
    write_csv(paths[1], SUPPORTS_HEADER, support_rows(ws))
    return paths


def _num(v):
    return float(v) if v is not None and np.isfinite(v) else None


def as_dict(ws) -> dict:
    """summary.json's "walls": per wall and stage the largest bending moment [kNm/m] and deflection
    [m] (+ towards larger x) with their depths and stds, per support and stage its force per metre run
    [kN/m] and per prop or anchor [kN] with stds (None before installation or without a band)."""
    walls = {}
    for w in ws.walls.values():
        stages = {}
        for k, stage in enumerate(w.stages):
            m, dm, sm = w.largest("M", k)
            u, du, su = w.largest("ux", k)
            stages[stage] = {"excavation_level_m": float(w.formation[k]), "M_max_kNm_per_m": _num(m),
                             "M_max_depth_m": _num(dm), "M_max_std": _num(sm), "ux_max_m": _num(u),
                             "ux_max_depth_m": _num(du), "ux_max_std": _num(su)}
        walls[w.name] = {"x_m": w.x, "thickness_m": w.thickness, "toe_m": w.toe, "stages": stages}
    supports = {}
    for s in ws.supports.values():
        stages = {}
        for k, stage in enumerate(s.stages):
            sd = None if s.std is None else s.std[k]
            stages[stage] = {"force_kN_per_m": _num(s.force[k]), "std_kN_per_m": _num(sd),
                             "force_per_support_kN": _num(s.per_support * s.force[k]) if s.spacing else None,
                             "std_per_support_kN": _num(s.per_support * sd) if s.spacing and sd is not None
                             else None}
        supports[s.name] = {"kind": s.kind, "wall": s.wall, "depth_m": s.depth, "spacing_m": s.spacing,
                            "installed": s.installed, "stages": stages}
    return {"z": ws.z, "parameters": list(ws.parameters), "walls": walls, "supports": supports}


def _pm(v: float, s, unit: str, z: float, digits: str = ".3g") -> str:
    u = f" {unit}" if unit else ""
    if s is None or not np.isfinite(s):
        return f"{v:{digits}}{u}"
    return f"{v:{digits}} ± {s:.2g}{u} (95 % [{v - z * s:{digits}}, {v + z * s:{digits}}])"


def report_section(ws) -> str:
    """The report's "Walls and supports": per wall the largest bending moment and deflection after each
    stage and where; per prop or anchor its force after each stage."""
    if ws is None:
        return ""
    lines = ["", "## Walls and supports", ""]
    if ws.banded:
        lines += [f"At the estimate, with the first-order 95 % band from C_p (± {ws.z:.3g} std) of the identified "
                  f"values ({', '.join(ws.parameters)}); the rest taken as exact. Per metre run of wall.", ""]
    else:
        lines += ["At the estimate (no identified values: no band). Per metre run of wall.", ""]
    for w in ws.walls.values():
        lines += [f"Wall '{w.name}' (x = {w.x:g} m, {w.thickness:g} m thick, from {w.top:g} m to its toe at "
                  f"{w.toe:g} m depth; deflection + towards the excavation, moment + with the "
                  f"{'retained' if w.pit_side < 0 else 'excavated'} side in tension):",
                  "", "| after stage | excavation level [m] | largest bending moment [kNm/m] | at depth [m] | "
                      "largest deflection [mm] | at depth [m] |", "|---|---|---|---|---|---|"]
        for k, stage in enumerate(w.stages):
            m, dm, sm = w.largest("M", k)
            u, du, su = w.largest("ux", k)
            if not np.isfinite(m):
                lines.append(f"| {stage} | {w.formation[k]:g} | not installed | | | |")
                continue
            t = 1e3 * w.pit_side  # deflection towards the excavation [mm]
            lines.append(f"| {stage} | {w.formation[k]:g} | {_pm(m, sm, '', ws.z)} | {dm:.1f} | "
                         f"{_pm(t * u, 1e3 * su, '', ws.z)} | {du:.1f} |")
        lines.append("")
    if ws.supports:
        stages = next(iter(ws.supports.values())).stages
        lines += ["Props (compression +) and anchors (tension +): axial force after each stage, per metre run "
                  "and, where a spacing is given, per prop or anchor:", "",
                  "| support | depth [m] | " + " | ".join(stages) + " |", "|---|---|" + "---|" * len(stages)]
        for s in ws.supports.values():
            cells = []
            for k in range(len(stages)):
                if not np.isfinite(s.force[k]):
                    cells.append("–")
                    continue
                sd = None if s.std is None else s.std[k]
                text = _pm(s.force[k], sd, "kN/m", ws.z)
                if s.spacing is not None:
                    text += f"; {s.spacing * s.force[k]:.3g} kN per {s.kind}" + (
                        f" ± {s.spacing * sd:.2g}" if sd is not None and np.isfinite(sd) else "")
                cells.append(text)
            where = f"{s.kind} on '{s.wall}'" + (f", every {s.spacing:g} m" if s.spacing is not None else "")
            lines.append(f"| {s.name} ({where}) | {s.depth:g} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += ["Every depth and stage: walls.csv; every support and stage: supports.csv."]
    return "\n".join(lines) + "\n"
