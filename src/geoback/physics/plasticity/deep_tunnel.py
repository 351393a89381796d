"""The deep circular tunnel as an FE verification case, and what to measure on its solution.

Geometry as ``kirsch_case`` of the FEM tests: radius R, axis at depth L, half-width L, depth 2L
(half model, symmetry axis x = 0), meshed by gmsh with element size ``size_tunnel`` at the wall
growing by ``growth`` per unit distance up to ``size_far``. Hydrostatic initial stress -p0 at
every point (no gravity), released on the wall by f = fe.load(-p0, -p0).

Measured on a solution (:func:`measure`):

* plastic radius: where the FE radial stress s_rr(r) reaches the critical pressure -p_cr of the
  closed form (the radial stress at the elastic-plastic boundary, a property of the yield
  criterion: s_rr = -p_cr <=> the elastic field touches yield). s_rr is C1 across R_p, so a
  least-squares cubic in r through the quadrature points within +-15 % of the outermost yielded
  point locates the crossing well below the element size;
* the outermost yielded quadrature point (a coarse, element-size check of the same);
* the wall displacement: mean radial displacement of the wall nodes (a rigid vertical
  translation of the tunnel, the far-boundary effect, cancels in the mean over the half circle).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geoback.case.loading import case_from_data
from geoback.physics.fem import FEModel
from geoback.physics.mesh import build_mesh


def deep_tunnel_model(R: float = 1.0, L: float = 50.0, size_tunnel: float = 0.1, size_far: float | None = None,
                      growth: float = 0.25) -> FEModel:
    case = case_from_data(dict(
        name="deep-tunnel",
        geometry=dict(radius=R, axis_depth=L, width=L, depth=2 * L),
        ground=dict(unit_weight=1.0, K0=1.0, layers=[dict(name="ground", top=0.0, E=1.0, nu=0.3)]),
        mesh=dict(size_tunnel=size_tunnel, size_far=size_far or L / 10, growth=growth),
    ))
    return FEModel(build_mesh(case), L, 2 * L, (0.0, -L), R)


def hydrostatic_load(fe: FEModel, p0: float):
    """Initial stress (4,) and excavation load (free dofs) of a hydrostatic p0 (> 0, compression)."""
    sv = np.full(len(fe.wall_points), -p0)
    return np.array([-p0, -p0, -p0, 0.0]), fe.load(sv, sv)


def polar(fe: FEModel, xy: np.ndarray):
    d = xy - fe.centre
    r = np.hypot(d[:, 0], d[:, 1])
    return r, d[:, 0] / r, d[:, 1] / r


@dataclass(frozen=True)
class Measured:
    plastic_radius: float  # from the radial stress crossing (nan if no point yielded)
    outermost_yielded: float  # radius of the outermost yielded quadrature point (R if none)
    wall_displacement: float  # mean radial wall displacement (outward positive)
    wall_spread: float  # (max - min) / |mean| of the radial wall displacement


def measure(fe: FEModel, points_xy: np.ndarray, sigma: np.ndarray, plastic: np.ndarray, u_free: np.ndarray,
            p_cr: float) -> Measured:
    """Plastic radius and wall displacement of one stage: sigma (npts, 4), plastic (npts,)."""
    r, cx, sy = polar(fe, points_xy)
    srr = sigma[:, 0] * cx ** 2 + sigma[:, 1] * sy ** 2 + 2 * sigma[:, 3] * cx * sy
    plastic = np.asarray(plastic).reshape(-1)
    outer = float(r[plastic].max()) if plastic.any() else fe.radius
    rp = np.nan
    if plastic.any():
        band = np.abs(r - outer) <= 0.15 * outer
        x = r[band] - outer
        coef = np.polyfit(x, srr[band] + p_cr, 3)
        roots = np.roots(coef)
        roots = roots[np.abs(roots.imag) < 1e-12].real
        if len(roots):
            rp = float(outer + roots[np.argmin(np.abs(roots))])
    wall = np.unique(fe.mesh.tunnel_edges)
    rw, cw, sw = polar(fe, fe.nodes[wall])
    u = fe.expand(u_free).reshape(-1, 2)[wall]
    ur = u[:, 0] * cw + u[:, 1] * sw
    return Measured(rp, outer, float(ur.mean()), float((ur.max() - ur.min()) / abs(ur.mean())))
