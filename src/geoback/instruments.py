"""Instruments as observation operators: readings x = P u - G c, covariance C_x (eqns 9-26).

P (m x nfree, sparse) picks displacement components out of the FE solution by shape-function
interpolation; G (m x k) applies the integration constants c of linewise instruments (A, B,
C and D of eqns 11, 15, 18), which are zero unless identified; C_x is block-diagonal over
instruments (eqn 9).
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from . import covariance as cov
from .case import Case, LoadedCase
from .errors import CaseError

LINEWISE = {"inclinometer": "inclinometer", "sliding_micrometer": "sliding_micrometer",
            "extensometer": "sliding_micrometer", "deflectometer": "deflectometer"}


@dataclass
class Reading:
    instrument: str
    kind: str
    station: int
    component: str
    x: float
    y: float


@dataclass
class InstrumentBlock:
    """One instrument's rows: sampling points, per-point direction, covariance, readings."""

    name: str
    kind: str
    points: np.ndarray  # (npts, 2) where displacements are sampled
    weights: np.ndarray  # (m, npts, 2): reading_i = sum_j weights[i, j] . u(point_j)
    labels: list[Reading]
    covariance: np.ndarray
    constants: np.ndarray  # G block (m x k)
    constant_names: list[str]
    measured: np.ndarray | None
    lengths: np.ndarray | None = None  # linewise only
    integration: np.ndarray | None = None  # W of eqns 11/15/18 (linewise only)
    constant_variances: dict = field(default_factory=dict)
    sigma: float = 1.0


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


def build_block(ins, loaded: LoadedCase, index: int, with_readings: bool = True) -> InstrumentBlock:
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
        C = np.eye(m) * ins.sigma ** 2
        block = InstrumentBlock(ins.name, kind, pts, w, labels, C, np.zeros((m, 0)), [], None, sigma=ins.sigma)
    elif kind == "convergence":
        a, b = np.asarray(ins.points[0], float), np.asarray(ins.points[1], float)
        if np.linalg.norm(b - a) == 0:
            raise loaded.error(("instruments", index, "points"), "the chord's two points coincide")
        d = (b - a) / np.linalg.norm(b - a)
        w = np.zeros((1, 2, 2))
        w[0, 0], w[0, 1] = -d, d
        labels = [Reading(ins.name, kind, 1, "chord", *(0.5 * (a + b)))]
        block = InstrumentBlock(ins.name, kind, np.array([a, b]), w, labels, np.eye(1) * ins.sigma ** 2,
                                np.zeros((1, 0)), [], None, sigma=ins.sigma)
    else:
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
        w = np.zeros((m, m, 2))
        w[np.arange(m), np.arange(m)] = direction
        comp = {"inclinometer": "ux", "sliding_micrometer": "along", "deflectometer": "normal"}[lkind]
        labels = [Reading(ins.name, kind, i + 1, comp, *pts[i]) for i in range(m)]
        names = cov.constant_names(lkind)
        variances = {n: getattr(ins, f"var_{n.lower()}") for n in names}
        C = cov.instrument_covariance(lkind, lengths, ins.sigma, variances)
        G = cov.constant_matrix(lkind, lengths)
        block = InstrumentBlock(ins.name, kind, pts, w, labels, C, G, [f"{n}[{ins.name}]" for n in names],
                                None, lengths=lengths, integration=cov.integration_matrix(lkind, lengths),
                                constant_variances=variances, sigma=ins.sigma)
    block.measured = _readings(ins, loaded, index, block) if with_readings else None
    return block


def _readings(ins, loaded: LoadedCase, index: int, block: InstrumentBlock) -> np.ndarray | None:
    m = len(block.labels)
    if ins.readings is not None and ins.readings_file is not None:
        raise loaded.error(("instruments", index, "readings_file"), "give either 'readings' or 'readings_file', not both")
    if ins.readings is not None:
        values = np.asarray(ins.readings, float)
        at = ("instruments", index, "readings")
    elif ins.readings_file is not None:
        at = ("instruments", index, "readings_file")
        values = read_readings_csv(loaded.folder / ins.readings_file, ins.name, loaded, at)
    else:
        return None
    if len(values) != m:
        raise loaded.error(at, f"expected {m} readings for instrument '{ins.name}' "
                               f"({'stations' if block.integration is not None else 'point components'}), found {len(values)}")
    if not np.all(np.isfinite(values)):
        raise loaded.error(at, f"instrument '{ins.name}' has a NaN or infinite reading "
                               f"(reading {int(np.flatnonzero(~np.isfinite(values))[0]) + 1})")
    if getattr(ins, "reading_type", "displacement") == "primary":
        values = block.integration @ values  # eqns 11, 15, 18 with the constants taken as zero
    return values


def read_readings_csv(path, name: str, loaded: LoadedCase, at: tuple) -> np.ndarray:
    """Readings from CSV: a column 'reading' (or 'value'); rows of other instruments skipped
    when an 'instrument' column is present."""
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    except FileNotFoundError:
        raise loaded.error(at, f"readings file not found: {path}") from None
    if not rows:
        raise loaded.error(at, f"readings file {path} has no rows")
    column = next((c for c in ("reading", "value", "measured") if c in rows[0]), None)
    if column is None:
        raise loaded.error(at, f"readings file {path} needs a column named 'reading' (found {list(rows[0])})")
    if "instrument" in rows[0]:
        rows = [r for r in rows if r["instrument"] == name]
    out = []
    for i, r in enumerate(rows):
        try:
            out.append(float(r[column]))
        except (TypeError, ValueError):
            raise loaded.error(at, f"{path}, data row {i + 1}: '{r[column]}' is not a number") from None
    return np.asarray(out)


def check_inside(case: Case, blocks: list[InstrumentBlock], loaded: LoadedCase) -> None:
    """Reject instrument points outside the ground or inside the excavated tunnel."""
    g = case.geometry
    tol = 1e-9 * max(g.width, g.depth)
    for i, b in enumerate(blocks):
        for j, (x, y) in enumerate(b.points):
            where = None
            if x < -tol or x > g.width + tol or y > tol or y < -g.depth - tol:
                where = (f"outside the ground (the model spans x in [0, {g.width:g}] m and depth "
                         f"[0, {g.depth:g}] m)")
            elif np.hypot(x, y + g.axis_depth) < g.radius - 1e-6 * g.radius:
                where = f"inside the excavated tunnel (radius {g.radius:g} m around depth {g.axis_depth:g} m)"
            if where:
                what = "point" if b.kind in ("points", "convergence") else "station"
                raise loaded.error(("instruments", i), f"{b.kind} '{b.name}': {what} {j + 1} at "
                                                       f"({x:g}, {y:g}) lies {where}")


@dataclass
class Observations:
    """All instruments stacked: x = P u - G c, with C_x = L L^t (eqn 9)."""

    blocks: list[InstrumentBlock]
    P: sp.csr_matrix
    G: np.ndarray
    constant_names: list[str]
    covariance: np.ndarray
    chol: np.ndarray
    measured: np.ndarray | None
    labels: list[Reading]
    identified_constants: tuple = ()

    @property
    def m(self) -> int:
        return self.P.shape[0]

    def whiten(self, r: np.ndarray) -> np.ndarray:
        """L^-1 r (eqn 53 as corrected: work with the whitened residual and sensitivity)."""
        return sla.solve_triangular(self.chol, r, lower=True)


def build_observations(loaded: LoadedCase, fe, identified_constants: set[str] = frozenset(),
                       with_readings: bool = True) -> Observations:
    """Stack every instrument of the case into one observation operator."""
    case = loaded.case
    if not case.instruments:
        raise loaded.error(("instruments",), "the case has no instruments: add at least one (see `geoback schema`)")
    blocks = [build_block(ins, loaded, i, with_readings) for i, ins in enumerate(case.instruments)]
    check_inside(case, blocks, loaded)
    return assemble_observations(blocks, fe, identified_constants)


def assemble_observations(blocks: list[InstrumentBlock], fe, identified_constants=frozenset()) -> Observations:
    if not blocks:
        raise CaseError("the case has no instruments")
    all_pts = np.vstack([b.points for b in blocks])
    Ix, Iy = fe.interpolation(all_pts)
    rows, Gs, covs, names, measured, labels = [], [], [], [], [], []
    offset = 0
    for b in blocks:
        n = len(b.points)
        wx = sp.csr_matrix(b.weights[:, :, 0])
        wy = sp.csr_matrix(b.weights[:, :, 1])
        rows.append(wx @ Ix[offset:offset + n] + wy @ Iy[offset:offset + n])
        offset += n
        C = b.covariance.copy()
        for j, cname in enumerate(b.constant_names):
            if cname in identified_constants:  # identified: its variance is no longer measurement error
                short = cname.split("[")[0]
                C -= b.constant_variances.get(short, 0.0) * np.outer(b.constants[:, j], b.constants[:, j])
        covs.append(C)
        Gs.append(b.constants)
        names += b.constant_names
        measured.append(b.measured)
        labels += b.labels
    P = sp.vstack(rows).tocsr()
    m = P.shape[0]
    G = np.zeros((m, len(names)))
    r0, c0 = 0, 0
    for g in Gs:
        G[r0:r0 + g.shape[0], c0:c0 + g.shape[1]] = g
        r0, c0 = r0 + g.shape[0], c0 + g.shape[1]
    C = sla.block_diag(*covs)
    chol_blocks = [cov.cholesky_factor(c, b.name) for c, b in zip(covs, blocks)]
    L = sla.block_diag(*chol_blocks)
    meas = None if any(v is None for v in measured) else np.concatenate(measured)
    return Observations(blocks, P, G, names, C, L, meas, labels, tuple(sorted(identified_constants)))
