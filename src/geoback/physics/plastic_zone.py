"""The plastic zone around the tunnel, stage by stage: what yielded, how far it reaches, its area.

Measured on the quadrature points of the elastoplastic solution (``plastic.PlasticSimulation``):
a point belongs to the plastic zone of a stage if it has yielded in some load increment up to that
stage (the zone does not shrink when a point unloads elastically). Per stage:

* ``max_radius``: distance from the tunnel axis of the outermost yielded point (R_p of the closed
  form for a deep tunnel under uniform stress; here it may differ around the tunnel);
* ``top_depth`` / ``bottom_depth``: the shallowest and deepest yielded point;
* ``area``: the yielded points' quadrature weights summed, doubled for the whole cross-section
  (the model is the half on one side of the symmetry axis);
* by angle from the crown (sectors of ``SECTOR`` degrees, 0 = crown, 90 = springline, 180 =
  invert): the radius of the outermost yielded point in the sector and its distance beyond the wall.

Resolution: one quadrature point, about a third of an element, so the extent is known to about
the element size there (see ``plasticity/deep_tunnel.py`` for a finer measure of R_p under uniform
stress). The equivalent plastic strain per cell is eps_p = sqrt(2/3 e_p : e_p) of the plastic
strain e_p = e - D^-1 (sigma - sigma0) (additive split: exact for linear elasticity, path-free).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

SECTOR = 15.0  # degrees
AXIS = "the tunnel axis"  # what a circular tunnel's radii are measured from (PlasticZone.about)
HEADER = ["stage", "release", "sector_deg", "angle_from_crown_deg", "plastic_radius_m", "extent_beyond_wall_m",
          "top_depth_m", "bottom_depth_m", "area_m2", "yielded_points"]


@dataclass(frozen=True)
class StageZone:
    stage: str
    release: float  # cumulative release fraction of the stage
    yielded_points: int
    max_radius: float  # m (nan if nothing yielded)
    top_depth: float
    bottom_depth: float
    area: float  # m2, whole cross-section
    sector_radius: np.ndarray  # (nsectors,) m, nan where nothing yielded in the sector


@dataclass(frozen=True)
class PlasticZone:
    """The plastic zone of every stage, and per-cell fields for figures (readers only)."""

    radius: float  # tunnel radius R
    centre: tuple  # (x, y) of the tunnel axis
    sectors: np.ndarray  # (nsectors,) centre angles from the crown [deg]
    stages: list[StageZone]
    mesh: object  # the ground's mesh (nodes, triangles)
    cell_yielded: np.ndarray  # (nstages, ne) share of each cell's area that has yielded
    cell_plastic_strain: np.ndarray  # (nstages, ne) equivalent plastic strain, cell mean
    values: dict = field(default_factory=dict)  # the named values it was computed at
    about: str = AXIS  # what the radii are measured from (a section with openings: the centroid of
    # its first opening, and `radius` that opening's equivalent radius, the circle of the same area)

    @property
    def any(self) -> bool:
        return any(s.yielded_points for s in self.stages)

    def rows(self) -> list[list]:
        """plastic_zone.csv: per stage a row for the whole zone (sector 'all'), then one per sector."""
        out = []
        for s in self.stages:
            R = self.radius
            out.append([s.stage, s.release, "all", "", s.max_radius, s.max_radius - R if s.yielded_points else 0.0,
                        s.top_depth, s.bottom_depth, s.area, s.yielded_points])
            for a, r in zip(self.sectors, s.sector_radius):
                lo, hi = a - SECTOR / 2, a + SECTOR / 2
                out.append([s.stage, s.release, f"{lo:g}-{hi:g}", a, r, (r - R) if np.isfinite(r) else 0.0,
                            "", "", "", ""])
        return out

    def as_dict(self) -> list[dict]:
        return [{"stage": s.stage, "release": s.release, "yielded_points": s.yielded_points,
                 "max_radius_m": s.max_radius, "max_radius_over_R": s.max_radius / self.radius,
                 "top_depth_m": s.top_depth, "bottom_depth_m": s.bottom_depth, "area_m2": s.area}
                for s in self.stages]

    def lines(self, heading: str = "Plastic zone") -> list[str]:
        """The report's section (Markdown) under `heading`."""
        out = ["", f"## {heading}", ""]
        if not self.any:
            return out + ["The ground stays elastic: no point reaches the Mohr-Coulomb strength at any stage."]
        out += ["| stage | release | max. radius [m] | R_p / R | depth range [m] | area [m²] |", "|---|---|---|---|---|---|"]
        for s in self.stages:
            if not s.yielded_points:
                out.append(f"| {s.stage} | {s.release:.3g} | elastic | - | - | 0 |")
                continue
            out.append(f"| {s.stage} | {s.release:.3g} | {s.max_radius:.3g} | {s.max_radius / self.radius:.3g} | "
                       f"{s.top_depth:.3g}-{s.bottom_depth:.3g} | {s.area:.3g} |")
        tunnel = self.about == AXIS
        R = "" if tunnel else f"; R = {self.radius:.3g} m, the radius of the circle of the opening's area"
        angle = "the crown" if tunnel else "the upward vertical through that centroid"
        out += ["", f"Max. radius: distance from {self.about} of the outermost yielded ground{R}; area over the whole "
                    f"cross-section; resolution about one element (plastic_zone.csv gives it by angle from {angle})."]
        return out


def measure(stages: list[str], release: np.ndarray, xy: np.ndarray, weights: np.ndarray, yielded: np.ndarray,
            centre, radius: float, mesh, plastic_strain: np.ndarray, values: dict | None = None,
            about: str = AXIS) -> PlasticZone:
    """The plastic zone from point data: xy (npts, 2), weights (npts,), yielded (nstages, npts) bool,
    plastic_strain (nstages, npts); points numbered element by element (nq per element)."""
    d = xy - np.asarray(centre, float)
    r = np.hypot(d[:, 0], d[:, 1])
    angle = np.degrees(np.arctan2(np.abs(d[:, 0]), d[:, 1]))  # 0 at the crown, 180 at the invert (x >= 0)
    sectors = np.arange(SECTOR / 2, 180.0, SECTOR)
    which = np.clip((angle // SECTOR).astype(int), 0, len(sectors) - 1)
    depth = -xy[:, 1]
    ne = len(mesh.triangles)
    nq = len(weights) // ne
    w = weights.reshape(ne, nq)
    zones = []
    for k, stage in enumerate(stages):
        y = yielded[k]
        per = np.full(len(sectors), np.nan)
        if y.any():
            np.fmax.at(per, which[y], r[y])
            zone = StageZone(stage, float(release[k]), int(y.sum()), float(r[y].max()), float(depth[y].min()),
                             float(depth[y].max()), float(2 * weights[y].sum()), per)
        else:
            zone = StageZone(stage, float(release[k]), 0, float("nan"), float("nan"), float("nan"), 0.0, per)
        zones.append(zone)
    share = (yielded.reshape(len(stages), ne, nq) * w).sum(axis=2) / w.sum(axis=1)
    strain = (plastic_strain.reshape(len(stages), ne, nq) * w).sum(axis=2) / w.sum(axis=1)
    return PlasticZone(radius, tuple(np.asarray(centre, float)), sectors, zones, mesh, share, strain,
                       dict(values or {}), about)


def equivalent_plastic_strain(strain: np.ndarray, dstress: np.ndarray, E: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """sqrt(2/3 e_p : e_p) at points: strain (npts, 3) = (exx, eyy, gxy) since the excavation began,
    dstress (npts, 4) = sigma - sigma0 (sxx, syy, szz, sxy), E and nu per point (plane strain: ezz = 0)."""
    sxx, syy, szz, sxy = dstress.T
    ee_xx = (sxx - nu * (syy + szz)) / E
    ee_yy = (syy - nu * (sxx + szz)) / E
    ee_zz = (szz - nu * (sxx + syy)) / E
    ee_xy = (1 + nu) / E * sxy  # tensor shear strain
    p_xx, p_yy, p_zz = strain[:, 0] - ee_xx, strain[:, 1] - ee_yy, -ee_zz
    p_xy = 0.5 * strain[:, 2] - ee_xy
    return np.sqrt(2.0 / 3.0 * (p_xx ** 2 + p_yy ** 2 + p_zz ** 2 + 2 * p_xy ** 2))
