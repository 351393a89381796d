"""How big a case's mesh will be, and what it will cost, known before gmsh runs.

gmsh meshes the half-model with the background size field of :mod:`geoback.physics.mesh`: the size
grows linearly from ``size_tunnel`` at the tunnel wall (and from ``size_instruments`` near the
instruments) by ``growth`` per metre of distance, up to ``size_far``. A triangulation with local
edge length h holds about ``ELEMENTS_PER_H2 / h²`` triangles per unit area, so the number of
triangles is that density integrated over the ground. :func:`estimate` integrates it on cells
refined until each is no larger than the local element size (the field is smooth there), so it
follows the size field exactly, tunnel, instruments and domain clipping included; the constant
was fitted to real gmsh meshes (``benchmarks/mesh_estimate.py``: the estimate is within 10 % of
gmsh's counts of elements and nodes over cases from 300 to 200,000 elements, growth up to 1; it
over-estimates refinement around instruments with a faster growth, by up to 60 % at growth 2).

Costs are in DOFs (two per node; quadratic triangles have about 2 nodes per triangle, linear
about 1/2) and in the peak memory of ``geoback run``, fitted to measured runs on the reference
machine (same benchmark). ``DEFAULT_MAX_DOFS`` is the default limit (``GEOBACK_MAX_DOFS`` in the
environment changes it): cases above it are refused before any meshing, with the estimate in the
message, unless ``allow_large`` (``--allow-large``) is given; ``HARD_MAX_DOFS`` is refused even then (gmsh and the sparse solvers index with 32-bit
integers, and no machine this runs on has the memory).

Each physics costs differently per DOF (``Work``, from the case: ``Work.of``). The one-step elastic
model holds one symmetric factor; a staged model with a lining holds SuperLU's factor with the wall
last and the wall's Schur complement; a Mohr-Coulomb run holds two unsymmetric factors (the Newton
matrix and the converged tangent), the stress history and the sensitivities at every quadrature
point, and factorises again at every Newton iteration of every plastic load increment. Memory is
``BYTES_PER_DOF[physics]`` per DOF above the interpreter's ``RUN_BASE_BYTES``, fitted to measured
peaks (``benchmarks/physics_costs.py``); a run that checks the discretisation error (``fit:
mesh_error``, the default) also solves once on a mesh twice as fine (four times the DOFs), counted
when that check is made (``check_fits``: it is skipped when it would need more memory than the
limit allows). The limit is one of memory: a physics that needs more per DOF is allowed
proportionally fewer DOFs (``Work.limit_dofs``), so every accepted case runs in about the memory the
elastic limit announces. The time of one forward run is estimated from its factorisations
(``Work.forward_seconds``): Mohr-Coulomb from the load increments of its fixed schedule
(``strength.stage_increments``; elastic spans are one increment, so this is an upper bound) and
``NEWTON`` factorisations each.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from geoback.case.schema import Case

# triangles = AREA * integral of dA/h² + BOUNDARY * (edges on the boundary) + INTERFACE * (edges on
# layer interfaces); 4/sqrt(3) = 2.31 would be equilateral triangles. Fitted to gmsh 4 meshes.
AREA_FACTOR = 2.26
BOUNDARY_FACTOR = 0.63
INTERFACE_FACTOR = 0.92
HARD_MAX_DOFS = 50_000_000
# peak resident memory of `geoback run` ~ BASE + PER_DOF * dofs, fitted to runs of the paper case
# from 9 k to 770 k DOFs (benchmarks/mesh_estimate.py --costs): 0.14 GB at 9 k DOFs, 0.65 GB at
# 127 k, 1.6 GB at 440 k (48 s), 2.7 GB at 770 k (95 s); linear elements 0.74 GB at 194 k
RUN_BASE_BYTES = 150e6
RUN_BYTES_PER_DOF = {1: 3_000.0, 2: 3_300.0}
DEFAULT_MAX_DOFS = 500_000  # default limit: `run` of such a case takes about 1 min and 1.8 GB
# bytes per DOF above RUN_BASE_BYTES of one forward run with the sensitivities of a fit, measured
# (benchmarks/physics_costs.py, quadratic elements): a staged case with a lining 8.4 k DOFs 0.17 GB,
# 30 k 0.37 GB, 83 k 0.97 GB; Mohr-Coulomb (three stages, four parameters) 5.2 k DOFs 0.16 GB,
# 30 k 0.46 GB, 55 k 0.79 GB, 100 k 1.31 GB (463 k DOFs ran out of 5.4 GB where 1.7 GB had been announced)
BYTES_PER_DOF = {"elastic": None, "staged": 10_400.0, "mohr-coulomb": 12_100.0}  # None: RUN_BYTES_PER_DOF
PHYSICS_WORDS = {"elastic": "linear-elastic ground", "staged": "staged construction",
                 "mohr-coulomb": "Mohr-Coulomb ground"}
NEWTON = 3  # factorisations per plastic load increment (Newton iterations and the converged tangent), measured 2.5-3
SECONDS_PER_FACTORISATION_DOF = 7.5e-6  # one Mohr-Coulomb factorisation with its assembly and return mapping,
# per DOF, on the 2-core reference machine under load (10 k DOFs 0.064 s, 55 k 0.27 s, 100 k 0.76 s)
FINE = 4.0  # the discretisation-error check's mesh (twice as fine) has at most about four times the DOFs


@dataclass(frozen=True)
class Work:
    """What a case asks of its mesh beyond its size: the physics, the load increments of one
    forward run, and whether `run` checks the discretisation error on a mesh twice as fine."""

    physics: str = "elastic"  # 'elastic' | 'staged' | 'mohr-coulomb'
    increments: int = 1  # load increments of one forward run (Mohr-Coulomb: the fixed schedule's)
    check: bool = True

    @classmethod
    def of(cls, case: Case) -> "Work":
        from geoback.case.strength import is_plastic, stage_increments

        check = case.fit.mesh_error != "ignore"
        if is_plastic(case):
            steps = _opening_steps(case) if hasattr(case.geometry, "openings") else None
            if steps is None:
                releases = [1.0] if case.construction is None else \
                    [float(s.release) for s in case.construction.stages if s.release is not None] or [1.0]
                releases = np.clip(np.nan_to_num(np.asarray(releases, float), nan=1.0, posinf=1.0), 0.0, 1e3)
                steps = np.diff(np.concatenate([[0.0], np.maximum.accumulate(releases)]))
            return cls("mohr-coulomb", int(sum(stage_increments(steps))), check)
        if case.construction is not None:
            return cls("staged", len(case.construction.stages), check)
        return cls("elastic", 1, check)

    def bytes_per_dof(self, order: int = 2) -> float:
        per = BYTES_PER_DOF.get(self.physics)
        return RUN_BYTES_PER_DOF.get(order, 3_300.0) if per is None else per * (1.0 if order == 2 else 0.9)

    def forward_bytes(self, dofs: float, order: int = 2) -> float:
        """Peak memory of one forward run with the sensitivities of a fit (bytes)."""
        return RUN_BASE_BYTES + self.bytes_per_dof(order) * dofs

    def limit_dofs(self, limit: float, order: int = 2) -> float:
        """The DOFs this physics may have for the memory `limit` DOFs of elastic ground need."""
        return limit * RUN_BYTES_PER_DOF.get(order, 3_300.0) / self.bytes_per_dof(order)

    @property
    def factorisations(self) -> int:
        """Factorisations of one forward run (an upper bound for Mohr-Coulomb: elastic spans cost one)."""
        return NEWTON * self.increments + 1 if self.physics == "mohr-coulomb" else 1 + (self.physics == "staged")

    def forward_seconds(self, dofs: float) -> float:
        """One forward run on the 2-core reference machine (Mohr-Coulomb; rough for the others)."""
        return self.factorisations * SECONDS_PER_FACTORISATION_DOF * dofs

    def describe(self, dofs: float) -> str:
        """'Mohr-Coulomb ground: 10 load increments a forward run (about 31 factorisations, ~2 s)'."""
        if self.physics != "mohr-coulomb":
            return PHYSICS_WORDS[self.physics]
        return (f"{PHYSICS_WORDS[self.physics]}: up to {self.increments} load increments a forward run (about "
                f"{self.factorisations} factorisations, ~{_seconds(self.forward_seconds(dofs))}; a fit takes 10 to "
                f"30 forward runs)")


def _opening_steps(case: Case):
    """The largest fraction each stage of a case with openings releases of any group (the increments of
    ``excavation_plastic.py`` follow it), or None if the construction does not read (its checks say why)."""
    from geoback.case.sequence import Sequence

    try:
        frac = np.real(Sequence.of(case).fractions(Sequence.of(case).values))
    except Exception:  # noqa: BLE001 - a construction that does not read is refused by its own checks
        return None
    steps = np.diff(np.vstack([np.zeros((1, frac.shape[1])), frac]), axis=0).max(axis=1, initial=0.0)
    return np.clip(np.nan_to_num(steps, nan=1.0, posinf=1.0), 0.0, 1e3)


def _seconds(s: float) -> str:
    if not math.isfinite(s):
        return "forever"
    if s < 60:
        return f"{_sig(max(s, 0.1))} s"
    if s < 3600:
        return f"{_sig(s / 60)} min"
    return f"{_sig(s / 3600)} h"


def max_dofs() -> float:
    """The default limit: DEFAULT_MAX_DOFS, or the environment variable GEOBACK_MAX_DOFS (a
    machine with more memory may raise it; tests lower it)."""
    import os

    text = os.environ.get("GEOBACK_MAX_DOFS", "").strip().replace("_", "")
    if text:
        try:
            value = float(text)
            if value > 0:
                return value
        except ValueError:
            pass
        from geoback.errors import GeobackError

        raise GeobackError(f"GEOBACK_MAX_DOFS: expected a positive number of DOFs, found '{text}'")
    return DEFAULT_MAX_DOFS


FIELDS = ("size_far", "size_tunnel", "size_instruments")
_MAX_CELLS = 200_000  # cells in flight while integrating (bounds the estimate's own work: ~0.1 s)


@dataclass(frozen=True)
class MeshEstimate:
    """Estimated size and cost of a case's mesh."""

    elements: float
    nodes: float
    dofs: float
    run_bytes: float  # peak memory of `geoback run`
    order: int
    by_field: dict = field(default_factory=dict)  # elements where each size setting rules
    work: Work = field(default_factory=Work)  # the physics it is estimated for
    fine_dofs: float | None = None  # DOFs of the discretisation-error check's mesh (staged, Mohr-Coulomb)
    check_skipped: str = ""  # why that check will be skipped ('' when it will be made)

    @property
    def worst(self) -> str:
        """The mesh setting responsible for most elements."""
        return max(self.by_field, key=self.by_field.get) if self.by_field else "size_far"

    def describe(self) -> str:
        """'about 2.1 M DOFs, ~9 GB'."""
        return f"about {_count(self.dofs)} DOFs, ~{_bytes(self.run_bytes)}"


def _sig(x: float) -> str:
    """Two significant digits, never in exponent form: 1.2, 12, 120."""
    text = f"{x:.2g}"
    return f"{float(text):.0f}" if "e" in text else text


def _count(n: float) -> str:
    if not math.isfinite(n):
        return "more than 10^300"
    if n >= 1e9:
        return f"{_sig(n / 1e9)} G"
    if n >= 1e6:
        return f"{_sig(n / 1e6)} M"
    if n >= 1e4:
        return f"{round(n, -3):,.0f}"
    return f"{round(n, -1):,.0f}" if n >= 100 else f"{n:.0f}"


def describe_bytes(b: float) -> str:
    """'1.8 GB', '210 MB'."""
    return _bytes(b)


def _bytes(b: float) -> str:
    if not math.isfinite(b):
        return "unbounded memory"
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if b >= scale:
            return f"{_sig(b / scale)} {unit}"
    return f"{b / 1e3:.0f} kB"


def estimate(inputs: dict, work: Work | None = None, limit: float | None = None) -> MeshEstimate:
    """Estimate from :func:`mesh_inputs` (a plain dict; no gmsh involved), for the physics of
    `work` (default: elastic ground); `limit` (DOFs of elastic ground, default ``max_dofs()``) decides
    whether the run's discretisation-error check is made (``check_fits``)."""
    order = int(inputs.get("order", 2))
    try:  # (absurd coordinates overflow: an infinite estimate, refused, never a numpy warning)
        with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
            counts, boundary = _integrate(inputs)
    except (ZeroDivisionError, OverflowError, ValueError, FloatingPointError, MemoryError):
        counts, boundary = {"size_far": math.inf}, math.inf
    counts = {k: (math.inf if math.isnan(v) else v) for k, v in counts.items()}
    boundary = math.inf if math.isnan(boundary) else boundary
    elements = float(sum(counts.values()))
    # Euler: a triangulation with T triangles and B boundary edges has (T + B)/2 + 1 vertices and
    # (3T + B)/2 edges; quadratic elements have a node on every edge as well
    nodes = 2 * elements + boundary + 1 if order == 2 else (elements + boundary) / 2 + 1
    dofs = 2.0 * nodes
    fine, skipped = None, ""
    if work is not None and work.check and BYTES_PER_DOF.get(work.physics) is not None and math.isfinite(dofs):
        fine = estimate(finer(inputs, 2.0)).dofs  # the discretisation-error check's mesh
        skipped = check_fits(work, fine, order, limit)
    return MeshEstimate(elements, nodes, dofs, run_bytes(dofs, order, work, limit, fine), order, counts,
                        work or Work(), fine, skipped)


def finer(inputs: dict, factor: float) -> dict:
    """Mesh inputs `factor` times finer (as ``refined_case``)."""
    si = inputs.get("size_instruments")
    return dict(inputs, size_tunnel=inputs["size_tunnel"] / factor, size_far=inputs["size_far"] / factor,
                size_instruments=si / factor if si else si)


def run_bytes(dofs: float, order: int = 2, work: Work | None = None, limit: float | None = None,
              fine_dofs: float | None = None) -> float:
    """Peak memory of `geoback run` at this many DOFs (bytes), for the physics of `work` (default
    elastic ground: fitted to whole runs, the check included); the larger of the fit's forward runs and
    the discretisation-error check's run on the mesh twice as fine (`fine_dofs`, default FINE times
    the DOFs), when that check is made."""
    if work is None or BYTES_PER_DOF.get(work.physics) is None:
        return RUN_BASE_BYTES + RUN_BYTES_PER_DOF.get(order, 3_300.0) * dofs
    peak = work.forward_bytes(dofs, order)
    fine_dofs = FINE * dofs if fine_dofs is None else fine_dofs
    if work.check and not check_fits(work, fine_dofs, order, limit):
        peak = max(peak, work.forward_bytes(fine_dofs, order))
    return peak


def budget_bytes(limit: float | None = None, order: int = 2) -> float:
    """The memory the DOF limit allows (`limit` DOFs of elastic ground; default ``max_dofs()``)."""
    return RUN_BASE_BYTES + RUN_BYTES_PER_DOF.get(order, 3_300.0) * (max_dofs() if limit is None else limit)


def check_fits(work: Work, fine_dofs: float, order: int = 2, limit: float | None = None) -> str:
    """'' when the discretisation-error check's run on `fine_dofs` fits in the memory the limit
    allows; else why it is skipped."""
    need, allowed = work.forward_bytes(fine_dofs, order), budget_bytes(limit, order)
    if need <= allowed:
        return ""
    return (f"the mesh twice as fine would have about {_count(fine_dofs)} DOFs and need ~{_bytes(need)} with "
            f"{PHYSICS_WORDS.get(work.physics, work.physics)} (more than the ~{_bytes(allowed)} the size limit allows)")


def _size_field(inputs: dict, pts: np.ndarray | None):
    """Vectorised background size h(x, y) of gmsh's field and the index of the ruling setting."""
    g = inputs["geometry"]
    R, a = float(g["radius"]), float(g["axis_depth"])
    t, far = float(inputs["size_tunnel"]), float(inputs["size_far"])
    # gmsh places a layer of elements, then sizes the next from where it stands: the spacing grows
    # geometrically, by (1 + growth) per layer, which is a linear field of slope log(1 + growth)
    growth = math.log1p(float(inputs["growth"]))
    si = inputs.get("size_instruments")

    def h(x: np.ndarray, y: np.ndarray, slack: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """`slack`: half-diagonal of the cell; distances are taken at the nearest point of it."""
        d = np.maximum(np.abs(np.hypot(x, y + a) - R) - slack, 0.0)
        ht = np.minimum(t + growth * d, far) if far > t else np.full_like(x, far)
        which = np.where(ht < far, 1, 0)
        size = ht
        if si and pts is not None and len(pts) and far > si:
            di = np.full_like(x, np.inf)
            for k in range(0, len(pts), 64):
                p = pts[k:k + 64]
                di = np.minimum(di, np.hypot(x[:, None] - p[None, :, 0], y[:, None] - p[None, :, 1]).min(axis=1))
            di = np.maximum(di - slack, 0.0)
            hi = np.clip(si + growth * (di - si), si, far)
            which = np.where(hi < size, 2, which)
            size = np.minimum(size, hi)
        return size, which

    return h


def _integrate(inputs: dict) -> tuple[dict[str, float], float]:
    """Triangles by ruling size setting, and the number of boundary edges."""
    g = inputs["geometry"]
    if "openings" in g:
        return _integrate_section(inputs)
    W, H, R, a = float(g["width"]), float(g["depth"]), float(g["radius"]), float(g["axis_depth"])
    pts = np.asarray(inputs.get("instrument_points") or [], float).reshape(-1, 2)
    h = _size_field(inputs, pts)
    side = min(W, H) / 4
    nx, ny = max(1, math.ceil(W / side)), max(1, math.ceil(H / side))
    if nx * ny > _MAX_CELLS:
        raise ValueError("degenerate domain")
    ix, iy = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    hx, hy = W / nx / 2, H / ny / 2
    cx, cy = (2 * ix.ravel() + 1) * hx, -(2 * iy.ravel() + 1) * hy
    totals = np.zeros(3)
    for level in range(60):
        half_diag = math.hypot(hx, hy)
        r = np.hypot(cx, cy + a)
        keep = r + half_diag > R  # cells wholly inside the excavated tunnel hold no ground
        cx, cy, r = cx[keep], cy[keep], r[keep]
        size, which = h(cx, cy, np.zeros_like(cx))
        split = 2 * max(hx, hy) > size
        last = level == 59 or 4 * int(split.sum()) > _MAX_CELLS
        done = ~split if not last else np.ones_like(split)
        area = 4 * hx * hy
        hc = size[done]
        if last:  # cells still larger than their elements: between the centre's size and that of
            lo, _ = h(cx[done], cy[done], np.full(int(done.sum()), half_diag))  # the point nearest the wall
            hc = np.where(split[done], np.sqrt(lo * hc), hc)
        inside = np.where(r[done] >= R, 1.0, 0.0) if 2 * max(hx, hy) < R else \
            np.clip((r[done] + half_diag - R) / (2 * half_diag), 0.0, 1.0)
        np.add.at(totals, which[done], area * inside / hc ** 2)
        if last:
            break
        cx, cy = cx[split], cy[split]
        hx, hy = hx / 2, hy / 2
        cx = np.concatenate([cx - hx, cx + hx, cx - hx, cx + hx])
        cy = np.concatenate([cy - hy, cy - hy, cy + hy, cy + hy])
        if len(cx) == 0:
            break
    totals *= AREA_FACTOR
    boundary, interfaces = _edges(inputs, h)
    totals[1] += BOUNDARY_FACTOR * boundary + INTERFACE_FACTOR * interfaces  # mostly along the wall
    return dict(zip(FIELDS, map(float, totals))), boundary


def _edges(inputs: dict, h) -> tuple[float, float]:
    """Element edges on the model's boundary (tunnel wall included) and on layer interfaces:
    the integral of ds/h along them."""
    g = inputs["geometry"]
    W, H, R, a = float(g["width"]), float(g["depth"]), float(g["radius"]), float(g["axis_depth"])
    s = np.unique(np.concatenate([np.linspace(0, 1, 2001), np.geomspace(1e-9, 1, 400),
                                  1 - np.geomspace(1e-9, 1, 400)]))

    def along(p0, p1) -> float:
        x = p0[0] + (p1[0] - p0[0]) * s
        y = p0[1] + (p1[1] - p0[1]) * s
        size, _ = h(x, y, np.zeros_like(x))
        ground = np.hypot(x, y + a) >= R
        return math.hypot(p1[0] - p0[0], p1[1] - p0[1]) * float(np.trapezoid(ground / size, s))

    outer = [((0, 0), (W, 0)), ((W, 0), (W, -H)), ((W, -H), (0, -H)), ((0, -H), (0, -(a + R))),
             ((0, -(a - R)), (0, 0))]
    boundary = sum(along(p0, p1) for p0, p1 in outer)
    theta = np.linspace(-math.pi / 2, math.pi / 2, 2001)
    x, y = R * np.cos(theta), -a + R * np.sin(theta)
    size, _ = h(x, y, np.zeros_like(x))
    boundary += R * float(np.trapezoid(1 / size, theta))
    interfaces = sum(along((0, -top), (W, -top)) for top in inputs.get("tops", [])[1:])
    return boundary, interfaces


def size_problem(inputs: dict, allow_large: bool = False, settings: dict | None = None,
                 max_dofs: float | None = None, work: Work | None = None) -> tuple[str, str] | None:
    """(mesh setting to blame, message) when the mesh would exceed the limit; None when it fits.

    `settings` maps a mesh setting to the value written in the case (None for a default), for
    the message. The message reads 'expected ..., found ...; lower ... or pass --allow-large'.
    `work`: the case's physics (``Work.of(case)``; default elastic ground), whose limit in DOFs is
    the elastic limit's memory (``Work.limit_dofs``).
    """
    work = work or Work()
    elastic_limit = HARD_MAX_DOFS if allow_large else (globals()["max_dofs"]() if max_dofs is None else max_dofs)
    est = estimate(inputs, work, None if allow_large else elastic_limit)
    limit = work.limit_dofs(elastic_limit, est.order)
    if est.dofs <= limit:
        return None
    worst = est.worst
    written = (settings or {}).get(worst)
    value = f"{worst} {written:g}" if isinstance(written, (int, float)) else f"{worst} (default {inputs.get(worst, 0):g})"
    cap = run_bytes(limit, est.order, replace(work, check=False))
    physics = "" if work.physics == "elastic" else f" for {PHYSICS_WORDS[work.physics]}"
    message = (f"expected mesh sizes giving at most {_count(limit)} DOFs{physics} (~{_bytes(cap)} to run), found "
               f"sizes giving {est.describe()} (about {_count(est.elements)} elements, mostly from {value}); ")
    if allow_large:
        message += "coarsen the mesh (larger sizes): this is beyond what geoback can solve"
    else:
        message += "coarsen the mesh (larger mesh sizes) or pass --allow-large"
    return worst, message


MESH_FORMAT = 5  # bump when the meshing procedure or the cache layout changes, to invalidate caches


def mesh_inputs(case: Case) -> dict:
    """Everything the mesh depends on (and nothing else); with openings, what the estimate of the
    section's mesh needs (``physics/section_mesh.py`` keys its own cache)."""
    g, m = case.geometry, case.mesh
    if hasattr(g, "openings"):
        return _section_inputs(case)
    return {
        "format": MESH_FORMAT,
        "geometry": g.model_dump(),
        "tops": [layer.top for layer in case.ground.layers],
        "names": [layer.name for layer in case.ground.layers],
        "size_tunnel": m.size_tunnel or g.radius / 8,
        "size_far": m.size_far or max(g.width, g.depth) / 12,
        "size_instruments": m.size_instruments,
        "instrument_points": instrument_refinement_points(case) if m.size_instruments else [],
        "order": m.order,
        "growth": m.growth,
    }


def instrument_refinement_points(case: Case) -> list[list[float]]:
    """Sample points along every instrument, where the mesh is refined if asked."""
    pts: list[list[float]] = []
    for ins in case.instruments:
        kind = ins.kind
        if kind == "points":
            pts += [list(p) for p in ins.points]
        elif kind == "convergence":
            pts += [list(p) for p in ins.points]
        elif kind == "inclinometer":
            for d in np.linspace(ins.head_depth, ins.toe_depth, 25):
                pts.append([ins.x, -float(d)])
        else:
            a, b = np.array(ins.start), np.array(ins.end)
            for s in np.linspace(0, 1, 25):
                pts.append(list(map(float, a + s * (b - a))))
    return pts


def refined_case(case, factor: float):
    """The same case meshed `factor` times finer (for data that avoids the inverse crime)."""
    sizes = mesh_inputs(case)
    mesh = case.mesh.model_copy(update={
        "size_tunnel": sizes["size_tunnel"] / factor,
        "size_far": sizes["size_far"] / factor,
        "size_instruments": (sizes["size_instruments"] / factor) if sizes["size_instruments"] else None,
    })
    return case.model_copy(update={"mesh": mesh})


# ---------------------------------------------------------------------------- sections with openings
def section_sizes(case: Case) -> tuple[float, float]:
    """Element size at the openings' walls and far away for a case with openings: the case's
    ``size_tunnel`` and ``size_far``, by default the smallest opening's equivalent radius / 8 and the
    model's larger side / 12 (as ``physics/section_mesh.default_sizes`` meshes it)."""
    from geoback.case.layout import polygon

    g, m = case.geometry, case.mesh
    radii = [math.sqrt(polygon(op).area / math.pi) for op in g.openings]
    return (m.size_tunnel or min(radii) / 8, m.size_far or max(g.width, g.depth) / 12)


FINE_GROWTH = 3.0  # gmsh grades away from edges shorter than the size field asks at about this rate (fitted:
# tests/test_section_size.py, the estimate within 8 % of gmsh over horseshoes, circles and polygons, lined or not)


def _section_inputs(case: Case) -> dict:
    g, m = case.geometry, case.mesh
    wall, far = section_sizes(case)
    linings = (case.construction.linings or []) if case.construction is not None else []
    return {
        "format": MESH_FORMAT,
        "geometry": g.model_dump(mode="json"),
        "tops": [layer.top for layer in case.ground.layers],
        "names": [layer.name for layer in case.ground.layers],
        "linings": [ln.model_dump(mode="json") for ln in linings],
        "walls": [[w.x, w.top, w.toe, w.thickness, w.layers] for w in _walls(case)],
        "size_tunnel": wall,
        "size_far": far,
        "size_instruments": m.size_instruments,
        "instrument_points": instrument_refinement_points(case) if m.size_instruments else [],
        "order": m.order,
        "growth": m.growth,
    }


def _walls(case: Case) -> list:
    from geoback.case.supports import walls

    try:
        return list(walls(case).values())
    except Exception:  # noqa: BLE001 - a wall the checks refuse (neither thickness nor EA and EI): not counted
        return []


def _section_curves(layout, linings: list, walls: list = ()) -> tuple[list, list, list]:
    """The curves the section mesh refines towards (every opening's wall, its cut lines within it, in a
    half-model the symmetry axis across it, the linings' bands' edges), as shapely geometries; the
    linings' and the retaining walls' bands (polygon, element size: t/2 of a lining, t/layers of a wall);
    and the curves meshed finer than the wall's size (the inner
    face of a band inside a wall that is not a circle is the sampled inset outline: its sides are
    ``layout.SAMPLES`` per turn), each with its edge length."""
    from shapely.geometry import LineString

    from geoback.case import layout as lay
    from geoback.case.schema import PlacedLining

    x0, x1, depth = lay.box(layout)
    ground = lay.ground_polygon(layout)
    curves, bands, fine = [], [], []
    for op in layout.openings:
        poly = lay.polygon(op)
        curves.append(poly.exterior.intersection(ground))
        for a, b in op.cuts:
            curves.append(_cut_within(a, b, poly))
        if layout.model == "half":
            curves.append(LineString([(0.0, 1.0), (0.0, -depth - 1.0)]).intersection(poly))
    for data in linings:
        try:
            lining = PlacedLining.model_validate(data)
            band = lay.lining_band(layout, lining).intersection(ground)
        except Exception:  # noqa: BLE001 - a band the checks refuse: no refinement counted for it
            continue
        if band.area <= 0:
            continue
        bands.append((band, lining.thickness / 2))
        curves.append(band.boundary)
        op = lay.opening_of(layout, lining.on) or lay.opening_of(layout, lay.regions(layout)[lining.on][0])
        if lining.side == "wall" and op.shape != "circle":
            # the band's inner face is meshed as the sampled inset outline: its short sides are edges
            inner = lay.polygon(op, inset=lining.thickness).exterior
            segment = inner.length / max(len(inner.coords) - 1, 1)
            fine.append((inner.intersection(band.buffer(1e-6 * lining.thickness)), segment))
    for x, top, toe, thickness, layers in walls:
        from shapely.geometry import box as shapely_box

        band = shapely_box(x - thickness / 2, -toe, x + thickness / 2, -top).intersection(ground)
        if band.area > 0:
            bands.append((band, thickness / layers))
            curves.append(band.boundary)
    return [c for c in curves if not c.is_empty], bands, [(c, s) for c, s in fine if not c.is_empty]


def _cut_within(a, b, poly):
    """The part of the straight cut line through a and b that lies in the opening."""
    from shapely.geometry import LineString

    size = math.hypot(poly.bounds[2] - poly.bounds[0], poly.bounds[3] - poly.bounds[1])
    dx, dy = b[0] - a[0], b[1] - a[1]
    n = math.hypot(dx, dy) or 1.0
    reach = 2 * size + math.hypot(a[0] - poly.centroid.x, a[1] - poly.centroid.y)
    line = LineString([(a[0] - reach * dx / n, a[1] - reach * dy / n), (b[0] + reach * dx / n, b[1] + reach * dy / n)])
    return line.intersection(poly)


def _samples(geoms, spacing: float) -> np.ndarray:
    """Points along line geometries at most `spacing` apart."""
    import shapely

    out = []
    for geom in geoms:
        for line in getattr(geom, "geoms", [geom]):
            if line.geom_type == "Polygon":
                line = line.exterior
            if line.length <= 0 or not hasattr(line, "interpolate"):
                continue
            n = max(2, int(math.ceil(line.length / spacing)) + 1)
            pts = shapely.line_interpolate_point(line, np.linspace(0.0, line.length, n))
            out.append(shapely.get_coordinates(pts))
    return np.vstack(out) if out else np.zeros((0, 2))


def _integrate_section(inputs: dict) -> tuple[dict[str, float], float]:
    """Triangles by ruling size setting, and the boundary edges, of a section with openings: the size
    field of ``physics/section_mesh.py`` (distance to the walls, cut lines and bands, graded by `growth`
    up to `size_far`; a band of thickness t meshed at min(size_tunnel, t/2)) integrated over the whole
    model (the openings are meshed too), as ``_integrate`` does around a circular tunnel."""
    from scipy.spatial import cKDTree
    from shapely import contains_xy

    from geoback.case import layout as lay
    from geoback.case.schema import Layout

    layout = Layout.model_validate(inputs["geometry"])
    x0, x1, depth = lay.box(layout)
    W, H = x1 - x0, depth
    t, far = float(inputs["size_tunnel"]), float(inputs["size_far"])
    growth = math.log1p(float(inputs["growth"]))
    curves, bands, fine = _section_curves(layout, inputs.get("linings") or [], inputs.get("walls") or [])
    spacing = min(t, far) / 4
    if sum(c.length for c in curves) / spacing > 4 * _MAX_CELLS:  # walls of millions of elements: beyond any limit
        return {"size_far": 0.0, "size_tunnel": math.inf, "size_instruments": 0.0}, math.inf
    wall_pts = _samples(curves, spacing)
    tree = cKDTree(wall_pts) if len(wall_pts) else None
    sized = [(band, min(t, size)) for band, size in bands]  # a band meshed at min(wall, its own size)
    fine = fine + [(band.boundary, tb) for band, tb in sized]  # gmsh grades away from a band's short edges
    fine_trees = [(cKDTree(p), s) for c, s in fine if s < t and len(p := _samples([c], s))]
    pts = np.asarray(inputs.get("instrument_points") or [], float).reshape(-1, 2)
    si = inputs.get("size_instruments")
    itree = cKDTree(pts) if (si and len(pts) and far > si) else None

    def h(x: np.ndarray, y: np.ndarray, slack: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if tree is not None:
            d, _ = tree.query(np.column_stack([x, y]))
            d = np.maximum(d - spacing / 2 - slack, 0.0)
        else:
            d = np.full_like(x, np.inf)
        ht = np.minimum(t + growth * d, far) if far > t else np.full_like(x, far)
        for ftree, s in fine_trees:
            df, _ = ftree.query(np.column_stack([x, y]))
            ht = np.minimum(ht, s + FINE_GROWTH * np.maximum(df - s / 2 - slack, 0.0))
        for band, tb in sized:
            ht = np.where(contains_xy(band, x, y), np.minimum(ht, tb), ht)
        which = np.where(ht < far, 1, 0)
        size = ht
        if itree is not None:
            di, _ = itree.query(np.column_stack([x, y]))
            di = np.maximum(di - slack, 0.0)
            hi = np.clip(si + growth * (di - si), si, far)
            which = np.where(hi < size, 2, which)
            size = np.minimum(size, hi)
        return size, which

    side = min(W, H) / 4
    nx, ny = max(1, math.ceil(W / side)), max(1, math.ceil(H / side))
    if nx * ny > _MAX_CELLS:
        raise ValueError("degenerate domain")
    ix, iy = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    hx, hy = W / nx / 2, H / ny / 2
    cx, cy = x0 + (2 * ix.ravel() + 1) * hx, -(2 * iy.ravel() + 1) * hy
    totals = np.zeros(3)
    for level in range(60):
        half_diag = math.hypot(hx, hy)
        size, which = h(cx, cy, np.zeros_like(cx))
        split = 2 * max(hx, hy) > size
        last = level == 59 or 4 * int(split.sum()) > _MAX_CELLS
        done = ~split if not last else np.ones_like(split)
        hc = size[done]
        if last:
            lo, _ = h(cx[done], cy[done], np.full(int(done.sum()), half_diag))
            hc = np.where(split[done], np.sqrt(lo * hc), hc)
        np.add.at(totals, which[done], 4 * hx * hy / hc ** 2)
        if last:
            break
        cx, cy = cx[split], cy[split]
        hx, hy = hx / 2, hy / 2
        cx = np.concatenate([cx - hx, cx + hx, cx - hx, cx + hx])
        cy = np.concatenate([cy - hy, cy - hy, cy + hy, cy + hy])
        if len(cx) == 0:
            break
    totals *= AREA_FACTOR

    def along(geoms) -> float:
        p = _samples(geoms, spacing)
        if len(p) < 2:
            return 0.0
        size, _ = h(p[:, 0], p[:, 1], np.zeros(len(p)))
        return float(sum(g.length for g in geoms)) * float(np.mean(1.0 / size))

    from shapely.geometry import LineString

    outer = [LineString([(x0, 0.0), (x1, 0.0)]), LineString([(x1, 0.0), (x1, -H)]), LineString([(x1, -H), (x0, -H)]),
             LineString([(x0, -H), (x0, 0.0)])]
    boundary = sum(along([line]) for line in outer)
    interfaces = sum(along([LineString([(x0, -top), (x1, -top)])]) for top in inputs.get("tops", [])[1:])
    interfaces += sum(along([c]) for c in curves)
    totals[1] += BOUNDARY_FACTOR * boundary + INTERFACE_FACTOR * interfaces
    return dict(zip(FIELDS, map(float, totals))), boundary
