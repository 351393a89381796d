"""Data worth: which candidate instrument would narrow the forecasts (or the parameters) most.

At the estimate the parameters' information is I = A'^t A' + C_p0^-1 (eqn 55; C_p = I^-1). A
candidate instrument c read at a stage adds its whitened rows A_c' = L_c^-1 A_c (information
A_c^t C_x,c^-1 A_c), with A_c its exact sensitivities (eqns 34-42, read through another survey on
the same factorisations) and C_x,c = L_c L_c^t its measurement covariance (eqns 10-20, integration
constants included; whitened by the seam, ``misfit.whiten_block``), so that after it

    C_p,c = (I + A_c'^t A_c')^-1,      C_q,c = F C_p,c F^t

(``LinearAnalysis.conditional`` of the fit's ``Reliability.linear``, and its prediction variance)

for the target forecasts q (F = dq/dp). Candidates are ranked by the root-mean-square std of the
target forecasts after them (objective 'forecasts'), or by ln det C_p,c (objective 'parameters':
the volume of the confidence ellipsoid; its reduction is reported as the factor by which the
ellipsoid's volume shrinks). Linear like C_p itself: it assumes the estimate does not move much
when the new readings come (checked by `studies/design_check.py`). No readings are needed for the
candidates: only where they are and how accurate they are.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from geoback.case.checks import expand_candidates
from geoback.inference.misfit import whiten_block
from geoback.observation.instruments import build_block
from geoback.physics.simulation import is_constant


@dataclass(frozen=True)
class DesignResult:
    objective: str  # 'forecasts' or 'parameters'
    targets: list[str]  # target forecasts (objective 'forecasts')
    names: list[str]  # candidates, in the case's order
    kinds: list[str]
    stages: list[str]
    family: list[int]  # index of the case's candidate each one comes from
    family_name: list[str]  # its name in the case
    varied: list[tuple | None]  # (field, value) of a `vary` candidate
    readings: list[int]
    before: float  # rms std of the targets, or ln det C_p, without any candidate
    after: np.ndarray  # the same with each candidate
    std_before: np.ndarray  # parameters' std now
    std_after: np.ndarray  # (candidates, parameters)
    target_rows: list[str]  # labels of the target forecast rows
    target_before: np.ndarray  # std of each target row now
    target_after: np.ndarray  # (candidates, rows)
    parameters: list[str]
    unit: str  # of the target forecasts
    seconds: float
    counts: dict
    discrimination: object = None  # discrimination.Discrimination of the two leading hypotheses (--separate)

    @property
    def reduction(self) -> np.ndarray:
        """Relative reduction of the objective: 1 - rms std after / before, or of the ellipsoid's
        volume 1 - sqrt(det C_p,c / det C_p)."""
        if self.objective == "forecasts":
            return 1.0 - self.after / self.before
        return 1.0 - np.exp(0.5 * (self.after - self.before))

    @property
    def ranking(self) -> np.ndarray:
        """Candidates from the best to the worst."""
        return np.argsort(-self.reduction, kind="stable")

    @property
    def best(self) -> str:
        return self.names[int(self.ranking[0])]


def candidate_blocks(loaded, default_stage: str) -> list[tuple[int, object, object]]:
    """(family index, candidate model, InstrumentBlock at its stage) of every candidate."""
    out = []
    for i, c in expand_candidates(loaded.case.design):
        block = build_block(c, loaded, i)
        out.append((i, c, block.at(c.read_at or default_stage)))
    return out


def case_candidates(analysis) -> list[tuple[int, object, object]]:
    """The case's candidates (`candidate_blocks`), read by default at the last stage with readings."""
    sim = analysis.simulation
    read_stages = [lab.stage for lab in sim.survey.labels]
    return candidate_blocks(analysis.loaded, read_stages[-1] if read_stages else sim.stages[-1])


def separate(analysis, d: DesignResult, progress=None) -> DesignResult:
    """`d` with the candidates' power to tell apart the two hypotheses `geoback diagnose` finds
    leading (discrimination.py); `Discrimination.nothing()` when diagnose refits none."""
    from dataclasses import replace

    from geoback.diagnosis import diagnose
    from geoback.worth.discrimination import Discrimination, discriminate, leading_pair

    diagnosis = diagnose(analysis, progress=progress)
    pair = leading_pair(diagnosis, analysis)
    if pair is None:
        return replace(d, discrimination=Discrimination.nothing())
    cands = case_candidates(analysis)
    return replace(d, discrimination=discriminate(pair[0], pair[1], [b for _, _, b in cands], d.names))


def require_design(loaded) -> None:
    """The case must have a design section (checked by `geoback design` before any work, and by ``design``)."""
    if loaded.case.design is None:
        raise loaded.error(("design",), "expected a design section with candidate instruments (see `geoback "
                                        "init`), found none")


def require_estimate(result, what: str = "design") -> None:
    """Candidates are compared at the estimate: an identification that did not converge is refused."""
    from geoback.errors import GeobackError

    if result.fit.status != "converged" or not result.fit.moved:
        raise GeobackError(f"{what}: the identification did not converge ({result.status}): candidates are compared "
                           "at the estimate; run `geoback run` and fix the case first")


def design(analysis, result, progress=None) -> DesignResult:
    """Rank the case's candidate instruments at the estimate of `result` (an identification of this
    analysis' case that converged: refused otherwise, as `geoback design` refuses it; module docstring)."""
    from geoback.worth.forecast import forecast

    t0 = time.perf_counter()
    require_design(analysis.loaded)
    analysis.check_identification(result, "design")
    require_estimate(result)
    loaded, sim = analysis.loaded, analysis.simulation
    spec = loaded.case.design
    before_counts = sim.counters.snapshot()
    params, p = result.parameters, result.fit.p
    names = list(params.names)
    physical = [n for n in names if not is_constant(n)]
    cols = [j for j, n in enumerate(names) if not is_constant(n)]
    values = {k: v for k, v in analysis.values_at(p).items() if not is_constant(k)}
    now = result.reliability.linear  # C_p at the estimate (eqn 55)
    objective = spec.objective or ("forecasts" if loaded.case.forecasts else "parameters")
    targets, F, labels, unit = [], np.zeros((0, len(names))), [], ""
    if objective == "forecasts":
        fc = result.forecasts if result.forecasts is not None else forecast(analysis, result, draws=0)
        targets = list(spec.forecasts or fc.names)
        rows = np.array([i for i, f in enumerate(fc.forecast) if f in targets], np.int64)
        F = fc.sensitivity[rows]
        labels = [f"{fc.forecast[i]}:{fc.quantity[i]}@{fc.position[i]:.4g}" for i in rows]
        unit = fc.unit[rows[0]]

    def measure(posterior):
        if objective == "forecasts":
            v = posterior.prediction_variance(F)
            return float(np.sqrt(np.mean(v))), np.sqrt(np.clip(v, 0, None))
        sign, logdet = np.linalg.slogdet(posterior.covariance)
        return float(logdet), np.zeros(0)

    before, target_before = measure(now)
    cands = case_candidates(analysis)
    after, t_after, s_after = [], [], []
    for k, (fam, c, block) in enumerate(cands):
        with sim.surveying([block]) as view:
            A = np.zeros((block.m, len(names)))
            A[:, cols] = view.predict(values, physical, sensitivities=True).A
        after_c = now.conditional(whiten_block(block, A))  # A_c' = L_c^-1 A_c joins A'
        a, t = measure(after_c)
        after.append(a)
        t_after.append(t)
        s_after.append(after_c.std)
        if progress is not None and (k + 1) % 10 == 0:
            progress(f"design: {k + 1} of {len(cands)} candidates")
    varied = []
    for fam, c, _ in cands:
        v = spec.candidates[fam].vary
        varied.append(None if not v else (next(iter(v)), getattr(c, next(iter(v)))))
    return DesignResult(objective, targets, [c.name for _, c, _ in cands], [c.kind for _, c, _ in cands],
                        [b.stage for _, _, b in cands], [f for f, _, _ in cands],
                        [spec.candidates[f].name for f, _, _ in cands], varied,
                        [b.m for _, _, b in cands], before, np.array(after),
                        now.std, np.array(s_after), labels, target_before,
                        np.array(t_after), names, unit, time.perf_counter() - t0,
                        sim.counters.since(before_counts))
