"""Instruments as observation operators: readings x = P u - G c (eqns 9-26), and each instrument's
measurement covariance C_x (eqns 10-20).

P (m x nfree, sparse) picks displacement components out of the FE solution by shape-function
interpolation; G (m x k) applies the integration constants c of linewise instruments (A, B, C
and D of eqns 11, 15, 18), which are zero unless identified. This module knows where and what
each instrument measures; the measured values live in ``readings`` and the statistics in
``misfit``.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp

from geoback.case import covariance as cov
from geoback.case.loading import Case, LoadedCase



@dataclass(frozen=True)
class Linewise:
    """What a kind of linewise instrument is, written once: its covariance structure (eqns 10-20,
    ``case/covariance.py``), the component its readings carry, what they measure in words, the
    unit of its primary readings, and what a moved reference end is called."""

    structure: str
    component: str
    measures: str
    primary_unit: str
    anchor: str  # the reference end as a person names it ('' for an inclinometer: its toe or head)


LINEWISE_KINDS = {
    "inclinometer": Linewise("inclinometer", "ux", "horizontal displacement", "rad", ""),
    "sliding_micrometer": Linewise("sliding_micrometer", "along", "displacement along the line", "m", "anchor"),
    "extensometer": Linewise("sliding_micrometer", "along", "displacement along the line", "m", "anchor"),
    "deflectometer": Linewise("deflectometer", "normal", "displacement normal to the line", "1/m", "reference end"),
}
LINEWISE = {kind: lw.structure for kind, lw in LINEWISE_KINDS.items()}
CONSTANT_STEMS = ("A", "B", "C", "D")
# Systematic errors of an inclinometer (named with the instrument: bias[I1], zoff[I1]); zero when not
# identified. bias: a constant offset of every primary reading (slope, rad), so the integrated
# readings carry bias * L_n, L_n the distance of station n from the reference end (eqn 15 with
# alpha_i + bias); zoff: the probe's depth positions shifted by zoff (m, positive deeper), so every
# sampling point (the reference end's too) is read zoff deeper. The observation operator is then
# built at the shifted points (exact, not a first-order correction), and dx/d zoff is the depth
# derivative of the FE interpolant there (the gradient of the element's shape functions).
ERROR_STEMS = {"bias": "rad", "zoff": "m"}


@dataclass(frozen=True)
class Reading:
    """Label of one reading: instrument, station (from the reference end), component, where."""

    instrument: str
    kind: str
    station: int
    component: str
    x: float
    y: float
    stage: str | None = None  # construction stage the reading was taken at
    survey: str | None = None  # the survey (its date or name) when the readings file tells surveys apart


@dataclass
class InstrumentBlock:
    """One instrument: sampling points, per-point direction, covariance of its readings."""

    name: str
    kind: str
    index: int  # position in the case's instrument list
    points: np.ndarray  # (npts, 2) where displacements are sampled
    weights: np.ndarray  # (m, npts, 2): reading_i = sum_j weights[i, j] . u(point_j)
    labels: list[Reading]
    covariance: np.ndarray  # C_x of the instrument's readings (eqns 10-20)
    constants: np.ndarray  # G block (m x k)
    constant_names: list[str]
    lengths: np.ndarray | None = None  # linewise only
    integration: np.ndarray | None = None  # W of eqns 11/15/18 (linewise only)
    constant_variances: dict = field(default_factory=dict)
    sigma: float = 1.0
    reading_type: str = "displacement"
    relative: bool = False  # readings relative to the reference end: the last sampling point
    stage: str | None = None
    along: np.ndarray | None = None  # linewise: unit direction along the line, away from the reference end
    measured: np.ndarray | None = None  # linewise: the direction each reading measures (eqns 11, 15, 18)
    reference_end: str = ""  # linewise, in words: 'toe' or 'head' (inclinometer), 'reference end' (others)
    kept: tuple | None = None  # rows of the whole instrument this block reads (None: all; ``without``)
    support: str | None = None  # a load cell: the prop or anchor whose force it reads
    survey: str | None = None  # the survey (date or name) of a dated readings file; None: one set a stage
    since: str | None = None  # installed after this stage: reads P (u_stage - u_since) (None: since the start)
    reading_set: str | None = None  # the key of its readings when not derived (an average of surveys)

    @property
    def set_name(self) -> str:
        """The key of this block's readings (``readings.CaseReadings``): the stage, or 'stage@survey'."""
        if self.reading_set is not None:
            return self.reading_set
        return self.stage if self.survey is None else f"{self.stage}@{self.survey}"

    @property
    def m(self) -> int:
        return len(self.labels)

    @property
    def stations(self) -> np.ndarray:
        """Where the readings are: the stations of a linewise instrument that are read (without the
        reference end a relative instrument also samples), the points of the others."""
        if self.lengths is None:
            return self.points
        return self.points[[lab.station - 1 for lab in self.labels]]

    def without(self, rows) -> "InstrumentBlock":
        """The instrument without the readings `rows` (indices into this block's rows), e.g. readings
        marked missing: its labels, weights, G and W rows kept in order, and C_x the marginal of the
        remaining readings (C_x[keep, keep]); the sampling points, lengths and constants' variances
        stay those of the instrument. ``kept`` names the rows of the whole instrument still read."""
        drop = {int(r) for r in rows}
        if not drop <= set(range(self.m)):
            raise IndexError(f"rows {sorted(drop - set(range(self.m)))} are not rows of '{self.name}' ({self.m})")
        keep = [i for i in range(self.m) if i not in drop]
        whole = self.kept if self.kept is not None else tuple(range(self.m))
        return replace(self, weights=self.weights[keep], labels=[self.labels[i] for i in keep],
                       covariance=self.covariance[np.ix_(keep, keep)], constants=self.constants[keep],
                       integration=None if self.integration is None else self.integration[keep],
                       kept=tuple(whole[i] for i in keep))

    @property
    def reference(self) -> np.ndarray | None:
        """Linewise: the reference end, the point the stations are counted from (station k lies
        lengths[0] + ... + lengths[k] along the line from it)."""
        if self.lengths is None:
            return None
        return self.points[0] - self.lengths[0] * self.along

    @property
    def reference_end_moved(self) -> str:
        """What a non-zero integration constant means for this instrument, in words."""
        if self.kind == "deflectometer":
            return "reference end moved and rotated"
        return f"{LINEWISE_KINDS[self.kind].anchor or self.reference_end} moved"

    @property
    def measures(self) -> str:
        """Linewise: what each reading measures, in words ('horizontal displacement', ...)."""
        return LINEWISE_KINDS[self.kind].measures

    def at(self, stage: str, survey: str | None = None, since: str | None = None, averaged: int = 1,
           reading_set: str | None = None) -> "InstrumentBlock":
        """The same instrument read at construction stage `stage` (in the survey `survey`), installed
        after stage `since` (its readings increments since then), as the average of `averaged`
        surveys (C_x / averaged: independent surveys)."""
        out = replace(self, stage=stage, survey=survey, since=since if since is not None else self.since,
                      reading_set=reading_set,
                      labels=[replace(lab, stage=stage, survey=survey) for lab in self.labels])
        if averaged > 1:
            out = replace(out, covariance=self.covariance / averaged,
                          constant_variances={k: v / averaged for k, v in self.constant_variances.items()})
        return out

    def covariance_given(self, identified: set[str] | frozenset = frozenset()) -> np.ndarray:
        """C_x with the variance of every identified integration constant removed: once identified,
        a constant is a parameter, not measurement error."""
        C = self.covariance.copy()
        for j, cname in enumerate(self.constant_names):
            if cname in identified:
                short = cname.split("[")[0]
                C -= self.constant_variances.get(short, 0.0) * np.outer(self.constants[:, j], self.constants[:, j])
        return C


def _lengths(ins) -> np.ndarray:
    if ins.lengths is not None:
        return np.asarray(ins.lengths, float)
    if ins.stations is not None:
        return cov.station_lengths(stations=ins.stations, spacing=ins.spacing)
    total = _line_length(ins)
    n = int(np.floor(total / ins.spacing + 1e-9))
    return cov.station_lengths(stations=max(n, 1), spacing=ins.spacing)


def _line_length(ins) -> float:
    if ins.kind == "inclinometer":
        return ins.toe_depth - ins.head_depth
    return float(np.hypot(ins.end[0] - ins.start[0], ins.end[1] - ins.start[1]))


def _line(ins) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Reference end, unit direction along the line, and the measured direction."""
    if ins.kind == "inclinometer":
        head, toe = np.array([ins.x, -ins.head_depth]), np.array([ins.x, -ins.toe_depth])
        start, end = (toe, head) if ins.reference == "toe" else (head, toe)
        d = (end - start) / np.linalg.norm(end - start)
        return start, d, np.array([1.0, 0.0])  # horizontal displacement u_x
    start, end = np.asarray(ins.start, float), np.asarray(ins.end, float)
    d = (end - start) / np.linalg.norm(end - start)
    if LINEWISE[ins.kind] == "sliding_micrometer":
        return start, d, d  # displacement along the line, positive from start to end
    return start, d, np.array([d[1], -d[0]])  # deflectometer: normal, d rotated clockwise


def build_block(ins, loaded: LoadedCase, index: int) -> InstrumentBlock:
    """Geometry, labels and covariance of one instrument of the case."""
    kind = ins.kind
    if kind == "points":
        pts = np.asarray(ins.points, float)
        comps = [0 if c == "ux" else 1 for c in ins.components]
        m = len(pts) * len(comps)
        w = np.zeros((m, len(pts), 2))
        labels = []
        for j in range(len(pts)):
            for k, c in enumerate(comps):
                w[j * len(comps) + k, j, c] = 1.0
                labels.append(Reading(ins.name, kind, j + 1, ins.components[k], *pts[j]))
        return InstrumentBlock(ins.name, kind, index, pts, w, labels, np.eye(m) * ins.sigma ** 2,
                               np.zeros((m, 0)), [], sigma=ins.sigma)
    if kind == "load_cell":  # the force is the simulation's (its support's connector), not a displacement
        from geoback.case.supports import connectors

        head = np.array([connectors(loaded.case)[ins.support].head], float)
        labels = [Reading(ins.name, kind, 1, "N", *head[0])]
        return InstrumentBlock(ins.name, kind, index, head, np.zeros((1, 1, 2)), labels, np.eye(1) * ins.sigma ** 2,
                               np.zeros((1, 0)), [], sigma=ins.sigma, support=ins.support)
    if kind == "convergence":
        a, b = np.asarray(ins.points[0], float), np.asarray(ins.points[1], float)
        if np.linalg.norm(b - a) == 0:
            raise loaded.error(("instruments", index, "points"), "the chord's two points coincide")
        d = (b - a) / np.linalg.norm(b - a)
        w = np.zeros((1, 2, 2))
        w[0, 0], w[0, 1] = -d, d
        labels = [Reading(ins.name, kind, 1, "chord", *(0.5 * (a + b)))]
        return InstrumentBlock(ins.name, kind, index, np.array([a, b]), w, labels, np.eye(1) * ins.sigma ** 2,
                               np.zeros((1, 0)), [], sigma=ins.sigma)
    lkind = LINEWISE[kind]
    try:
        lengths = _lengths(ins)
    except ValueError as exc:
        raise loaded.error(("instruments", index), str(exc)) from None
    if lengths.sum() > _line_length(ins) * (1 + 1e-9):
        raise loaded.error(("instruments", index, "lengths" if ins.lengths else "spacing"),
                           f"the stations reach {lengths.sum():g} m from the reference end, beyond the "
                           f"instrument's length {_line_length(ins):g} m")
    start, d, direction = _line(ins)
    pts = start[None] + np.cumsum(lengths)[:, None] * d[None]
    m = len(pts)
    relative = bool(getattr(ins, "readings_relative", False))
    w = np.zeros((m, m + relative, 2))
    w[np.arange(m), np.arange(m)] = direction
    if relative:  # u(station) - u(reference end): movements relative to the end the readings start from
        w[:, m] = -direction
        pts = np.vstack([pts, start])
    comp = LINEWISE_KINDS[kind].component
    labels = [Reading(ins.name, kind, i + 1, comp, *pts[i]) for i in range(m)]
    names = cov.constant_names(lkind)
    variances = {n: getattr(ins, f"var_{n.lower()}") for n in names}
    return InstrumentBlock(ins.name, kind, index, pts, w, labels,
                           cov.instrument_covariance(lkind, lengths, ins.sigma, variances),
                           cov.constant_matrix(lkind, lengths), [f"{n}[{ins.name}]" for n in names],
                           lengths=lengths, integration=cov.integration_matrix(lkind, lengths),
                           constant_variances=variances, sigma=ins.sigma, reading_type=ins.reading_type,
                           relative=relative, along=d, measured=direction,
                           reference_end=ins.reference if kind == "inclinometer" else "reference end")


def mirrored(block: InstrumentBlock) -> InstrumentBlock:
    """A block of a half-model with points on the other side of the symmetry axis (x < 0) read at their
    mirror images: u_x(-x, y) = -u_x(x, y), u_y(-x, y) = u_y(x, y) (the model is symmetric)."""
    left = block.points[:, 0] < 0
    if not left.any():
        return block
    points = block.points.copy()
    points[left, 0] *= -1
    weights = block.weights.copy()
    weights[:, left, 0] *= -1
    return replace(block, points=points, weights=weights)


def check_inside(case: Case, blocks: list[InstrumentBlock], loaded: LoadedCase) -> list[InstrumentBlock]:
    """Reject instrument points outside the ground or inside the excavated tunnel; with openings in a
    half-model, points at x < 0 are read at their mirror images (with a notice). Returns the blocks."""
    g = case.geometry
    if hasattr(g, "openings"):
        return _check_in_section(g, blocks, loaded)
    tol = 1e-9 * max(g.width, g.depth)
    for b in blocks:
        for j, (x, y) in enumerate(b.points):
            where = None
            if x < -tol or x > g.width + tol or y > tol or y < -g.depth - tol:
                where = (f"outside the ground (the model spans x in [0, {g.width:g}] m and depth "
                         f"[0, {g.depth:g}] m)")
            elif np.hypot(x, y + g.axis_depth) < g.radius - 1e-6 * g.radius:
                where = f"inside the excavated tunnel (radius {g.radius:g} m around depth {g.axis_depth:g} m)"
            if where:
                what = "point" if b.kind in ("points", "convergence") else "station"
                raise loaded.error(("instruments", b.index), f"{b.kind} '{b.name}': {what} {j + 1} at "
                                                             f"({x:g}, {y:g}) lies {where}")


def case_blocks(loaded: LoadedCase) -> list[InstrumentBlock]:
    """Every instrument of the case (geometry, labels, covariance), checked to lie in the ground;
    stage-less (``readings.survey_blocks`` places them at the stages they were read)."""
    case = loaded.case
    if not case.instruments:
        raise loaded.error(("instruments",), "the case has no instruments: add at least one (see `geoback schema`)")
    blocks = [replace(build_block(ins, loaded, i), since=getattr(ins, "installed_after", None))
              for i, ins in enumerate(case.instruments)]
    return check_inside(case, blocks, loaded) or blocks


_MIRRORED_SAID: set = set()  # (case file, instrument) whose mirroring was said


def _check_in_section(g, blocks: list[InstrumentBlock], loaded: LoadedCase) -> list[InstrumentBlock]:
    """Points inside the section's box (what is excavated depends on the stage: the simulation refuses
    readings of excavated ground); in a half-model, points at x < 0 mirrored with a notice."""
    import sys

    half = g.model == "half"
    lo, hi = (-g.width, g.width) if half else (-g.width / 2, g.width / 2)
    tol = 1e-9 * max(g.width, g.depth)
    out = []
    for b in blocks:
        for j, (x, y) in enumerate(b.points):
            if not (lo - tol <= x <= hi + tol and -g.depth - tol <= y <= tol):
                what = "point" if b.kind in ("points", "convergence") else "station"
                raise loaded.error(("instruments", b.index), f"{b.kind} '{b.name}': expected every {what} inside the "
                                                             f"ground (x between {lo:g} and {hi:g} m, y between "
                                                             f"{-g.depth:g} and 0 m), found {what} {j + 1} at ({x:g}, {y:g})")
        if half and (b.points[:, 0] < -tol).any():
            said = (str(loaded.path), b.name) if loaded.path is not None else None
            if said is None or said not in _MIRRORED_SAID:  # once per instrument of a case file (validate and
                _MIRRORED_SAID.add(said)  # run build it twice)
                print(f"notice: {b.kind} '{b.name}': points at x < 0 are read at their mirror images (a half-model "
                      f"is symmetric about x = 0: u_x changes sign)", file=sys.stderr, flush=True)
            b = mirrored(b)
        out.append(b)
    return out


def is_instrument_error(name: str) -> bool:
    """Systematic-error terms of an inclinometer: bias[I1], zoff[I1]."""
    return name.split("[")[0] in ERROR_STEMS and name.endswith("]")


@dataclass
class Survey:
    """All instruments stacked: x = P u - G c (eqn 9's block structure, one row per reading), plus
    the inclinometers' systematic errors (``ERROR_STEMS``): x += E b for the bias shifts b, and the
    depth offsets, with which P is read at shifted points (``operator``).

    P holds the m reading rows; ``operator(values)`` stacks below them the rows D of the depth
    derivatives dx/dz of every inclinometer's readings (``depth_rows``): a physics that reads depth
    offsets (``Simulation.reads_depth_offsets``) computes ``operator(values) @ u`` and
    ``operator(values) @ du/dv`` and `Simulation.predict` splits them, so a depth offset costs no
    solve and its sensitivity D u is exact. An inclinometer read at several construction stages
    has one bias shift over all its surveys and no depth offset."""

    blocks: list[InstrumentBlock]
    P: sp.csr_matrix  # m x nfree, at zero depth offsets
    G: np.ndarray  # m x k
    constant_names: list[str]
    labels: list[Reading]
    error_names: list[str] = field(default_factory=list)  # bias[I1], zoff[I1], ... (inclinometers)
    bias_columns: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # m x (number of bias names)
    depth_rows: dict = field(default_factory=dict)  # zoff[I1] -> (its reading rows, its rows of P beyond m)
    fe: object = None  # what P interpolates on (``interpolation(points, derivative)``), to read elsewhere
    D: sp.csr_matrix | None = None  # the depth-derivative rows (``depth_rows``), at zero depth offsets
    _shifted: dict = field(default_factory=dict, repr=False)

    @property
    def m(self) -> int:
        return len(self.labels)

    def offsets(self, values) -> tuple:
        """The depth offsets set in `values`, (name, metres) for every non-zero one, sorted."""
        return tuple(sorted((n, float(np.real(values[n]))) for n in self.depth_rows if values.get(n, 0) != 0))

    def operator(self, values) -> sp.csr_matrix:
        """[P; D] with every inclinometer read at its depth offset in `values`: the instruments'
        sampling points moved zoff deeper, interpolated anew (a few remembered)."""
        key = self.offsets(values)
        if key not in self._shifted:
            if not key:
                full = self.P if self.D is None or self.D.shape[0] == 0 else sp.vstack([self.P, self.D]).tocsr()
            else:
                shift = dict(key)
                blocks = [replace(b, points=b.points - np.array([0.0, shift.get(f"zoff[{b.name}]", 0.0)]))
                          for b in self.blocks]
                if len(self._shifted) >= 8:
                    self._shifted.pop(next(k for k in self._shifted if k))
                full = _operator(blocks, self.fe)[0]
            self._shifted[key] = full
        return self._shifted[key]

    def rows(self, name: str) -> slice:
        """Rows of an instrument's readings."""
        start = 0
        for b in self.blocks:
            if b.name == name:
                return slice(start, start + b.m)
            start += b.m
        raise KeyError(name)

    def constant_column(self, name: str) -> np.ndarray:
        """d x / d c for an integration constant c (eqns 11, 15, 18): -G[:, c]."""
        return -self.G[:, self.constant_names.index(name)]

    def bias_column(self, name: str) -> np.ndarray:
        """d x / d bias for an inclinometer's bias shift: L_n at its stations, 0 elsewhere."""
        return self.bias_columns[:, [n for n in self.error_names if n.startswith("bias[")].index(name)]


def bias_shift_column(block: InstrumentBlock) -> np.ndarray:
    """Displacement error of a linewise instrument's readings per unit offset of every primary
    reading: W 1 (eqns 11, 15, 18), for an inclinometer L_n, the distance from the reference end."""
    return block.integration @ np.ones(len(block.lengths))


def stage_constants(blocks: list[InstrumentBlock]) -> list[InstrumentBlock]:
    """An instrument read at several construction stages has integration constants per survey (each
    survey's reference end has its own error or movement): A[X1] becomes A[X1.stage] on each."""
    count: dict[str, int] = {}
    for b in blocks:
        for n in b.constant_names:
            count[n] = count.get(n, 0) + 1
    out = []
    for b in blocks:
        if any(count[n] > 1 for n in b.constant_names):
            b = replace(b, constant_names=[f"{n[:-1]}.{b.set_name}]" if count[n] > 1 else n for n in b.constant_names])
        out.append(b)
    return out


def _operator(blocks: list[InstrumentBlock], fe) -> tuple[sp.csr_matrix, dict]:
    """[P; D]: the readings' interpolation and, below it, the depth derivative of every
    inclinometer's readings (read zoff deeper: d/d zoff u(x, y - zoff) = -du/dy); and where D's
    rows are (zoff[I1] -> (reading rows, rows of D))."""
    all_pts = np.vstack([b.points for b in blocks])
    Ix, Iy = fe.interpolation(all_pts)
    incl = any(b.kind == "inclinometer" for b in blocks)
    Dx, Dy = fe.interpolation(all_pts, derivative=1) if incl else (None, None)  # d u / d y
    rows, extra, depth_rows = [], [], {}
    m = sum(b.m for b in blocks)
    surveys = _survey_count(blocks)
    offset = r0 = 0
    for b in blocks:
        n = len(b.points)
        wx = sp.csr_matrix(b.weights[:, :, 0])
        wy = sp.csr_matrix(b.weights[:, :, 1])
        rows.append(wx @ Ix[offset:offset + n] + wy @ Iy[offset:offset + n])
        if b.kind == "inclinometer" and surveys[b.name] == 1:
            start = m + sum(r.shape[0] for r in extra)
            extra.append(-(wx @ Dx[offset:offset + n] + wy @ Dy[offset:offset + n]))
            depth_rows[f"zoff[{b.name}]"] = (slice(r0, r0 + b.m), slice(start, start + b.m))
        offset += n
        r0 += b.m
    return sp.vstack(rows + extra).tocsr(), depth_rows


def _survey_count(blocks: list[InstrumentBlock]) -> dict[str, int]:
    """How many surveys (construction stages) of each instrument `blocks` hold."""
    count: dict[str, int] = {}
    for b in blocks:
        count[b.name] = count.get(b.name, 0) + 1
    return count


def build_survey(blocks: list[InstrumentBlock], fe) -> Survey:
    """The observation operator of `blocks` on the FE model `fe` (shape-function interpolation),
    with the depth-derivative rows and bias columns of every inclinometer (``Survey``)."""
    blocks = stage_constants(blocks)
    full, depth_rows = _operator(blocks, fe)
    Gs, names, labels = [], [], []
    error_names, bias_cols = [], {}
    surveys = _survey_count(blocks)
    m = sum(b.m for b in blocks)
    r0 = 0
    for b in blocks:
        if b.kind == "inclinometer":
            bias = f"bias[{b.name}]"
            if bias not in bias_cols:
                bias_cols[bias] = np.zeros(m)
                error_names += [bias] + ([f"zoff[{b.name}]"] if surveys[b.name] == 1 else [])
            bias_cols[bias][r0:r0 + b.m] = bias_shift_column(b)
        r0 += b.m
        Gs.append(b.constants)
        names += b.constant_names
        labels += b.labels
    G = np.zeros((m, len(names)))
    r0, c0 = 0, 0
    for g in Gs:
        G[r0:r0 + g.shape[0], c0:c0 + g.shape[1]] = g
        r0, c0 = r0 + g.shape[0], c0 + g.shape[1]
    E = np.column_stack(list(bias_cols.values())) if bias_cols else np.zeros((m, 0))
    return Survey(blocks, full[:m], G, names, labels, error_names, E, depth_rows, fe, full[m:])
