"""Hypothesis 'the ground yields around the tunnel': a Mohr-Coulomb plastic zone the linear-elastic
baseline leaves out, tested by a likelihood-ratio refit rather than a score test.

Why not a score test. Every other hypothesis of the library is scored at the baseline optimum by
the projection of the residual on its sensitivity columns (procedure.py, step 3). Yielding has no
such column: the elastic baseline is the plastic model at c' = infinity (or at any cohesion above
what the elastic stresses need), where no point is plastic and every derivative of the readings
with respect to the strength is exactly zero. The score statistic is then 0 whatever the readings,
so it cannot rank the hypothesis. Yielding is therefore tested as a likelihood ratio of two fits:

1. Screen (cheap, at the baseline optimum): the elastic stresses of the fit, per element near the
   tunnel (centroid within SCREEN_RADIUS * R of the axis), ask for a cohesion
       c_req = [(s1 - s3) + (s1 + s3) sin phi] / (2 cos phi)    (s1 >= s3 the in-plane principal
   stresses, tension positive; phi = PHI) to stay within the Mohr-Coulomb strength; c_crit is the
   largest of them in each layer. The hypothesis is put forward for a layer when c_crit exceeds
   the strength the weakest plausible ground of that stiffness would have, E / STIFFNESS_TO_STRENGTH
   (stiffness-to-strength ratios of soils and weak rocks lie roughly between 100 and 2000): were
   even that ground to stay elastic, no plausible strength could make it yield. The in-plane
   stresses give a lower bound of c_req (an out-of-plane stress outside them only adds to it).
2. Refit from a yielding state: the layer made mohr-coulomb with phi' = PHI (a plausible default,
   fixed: a tunnel's readings mostly tell the strength at the wall's confinement, which c' then
   carries) and psi = PSI, its cohesion c' identified together with the baseline's parameters,
   starting from c_crit / MARGIN - the elastic stresses exceed that strength by MARGIN at the
   wall, a small plastic zone from which the fit can grow or shrink it (c' up to 2 c_crit: an
   elastic ground again) - and from half that (a wider zone), keeping the better fit.
   A refit that stalls (c' walked to the elastic end of its range, or no better than the elastic
   fit) is started once more from CONTINUATION times the screen's start (a wider zone still).
   Where the readings determine c', phi' is freed too (from PHI, within PHI_RANGE) from the c'
   refit's optimum, and that refit is kept when its AIC is lower and both are determined (the
   readings of a tunnel mostly tell the strength at the wall's confinement; where they also tell
   phi', holding it at 30 deg biased c' and gave intervals that never held the truth, issue 24).
3. The strength the readings determine (``strength_profile``), for an accepted yielding cause whose
   phi' and psi were assumed: the final joint fit again with (phi', psi) held at the points of a grid,
   PROFILE_PHI x PROFILE_PSI (c' and every other parameter fitted, each fit started from its neighbour's
   optimum with the unconfined strength s_c = 2 c' cos phi' / (1 - sin phi') kept), outwards from PHI
   along phi' until J rises by more than chi^2_1(95 %) = 3.84. Per psi, J(phi') is interpolated by a
   cubic spline, ln c' and its linearised std linearly; c' with phi' and psi profiled out is the union
   over them of {c' : J(c', phi', psi) <= J_min + 3.84}, each slice linearised in ln c'. That is the
   95 % profile-likelihood interval of c' allowing for phi' anywhere in 20-40 deg and psi in 0-10 deg:
   the interval at the assumed angles alone never held the truth where they differ (issue 24: strengths
   off by -18 to +64 % with +-5 % intervals; cases/concealed/yielding.yaml, c' = 45 kPa with phi' = 28
   and psi = 5 deg: c' 39.9 +- 0.4 kPa at 30 and 0 deg). The same for s_c and for phi' itself; an end
   of phi' still inside at the last angle fitted is open (the readings do not bound it there).
4. Where the grid's best angles lower J by more than ADOPT (chi^2_2 at 1 %: two angles chosen, and a
   change of the model must be a strong finding) the model takes them (``adopt``), in the round that
   accepts yielding: its fit again with the layer's phi' and psi set in its case, so that the next
   rounds, the final joint fit, its intervals, the adequacy check and the amended case are those of the
   angles the readings favour (measured: the heading-and-bench section, truth psi = 5 deg, J 284 with
   psi = 0 assumed and 130 at psi = 5: its final model then passes its chi^2 test, p = 0.074). Where
   other causes are accepted after it, the profile is made again in the final model.
5. The likelihood-ratio test dJ ~ chi^2(1) (chi^2(2) with phi' freed) as for the other refits, in
   the same Bonferroni family.
   The null (c' at or above c_crit, every point elastic) lies on the boundary of the parameter
   space, where the statistic is a 50:50 mixture of 0 and chi^2(1): the chi^2(1) reference is
   conservative.

A refit runs only when the baseline is not adequate (procedure.py): readings that an elastic model
explains are never called yielding. Not proposed when the simulation already yields, or for a circular
tunnel's case with a lining (a lining on yielding ground is not modelled there). With openings the
screen takes the ground within (SCREEN_RADIUS - 1) equivalent radii of a wall, after every stage,
and the refit is the factory's yielding simulation of the section (``physics/excavation_plastic.py``).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from geoback.case.loading import Parameter
from geoback.errors import ForwardFailure
from geoback.physics.extensions import EXTENSIONS
from geoback.diagnosis.refit import REFIT_ITERATIONS, compare, fit_and_assess, judge, lr_objective
from geoback.diagnosis.results import Scored
from geoback.diagnosis.hypotheses import Hypothesis

PHI = 30.0  # degrees: friction angle of the refit (fixed)
PSI = 0.0  # degrees: dilation angle of the refit (fixed; no volume change in shear)
MARGIN = 1.5  # the refit starts where the elastic stresses exceed the strength by this factor at the wall
START_FACTORS = (0.5, 1.0)  # ... and from half that cohesion: from the small zone alone, the fit (E still the
# elastic fit's, too soft for yielding ground) can walk c' up into the elastic region, where every
# gradient in c' vanishes and it stops (measured: 3 of 18 yielding cases of the accuracy benchmark;
# the half start names 2 of them, bench-047 and bench-054 of `--staged 45 --yielding 10`)
STIFFNESS_TO_STRENGTH = 2000.0  # E / c of the weakest plausible ground
SCREEN_RADIUS = 1.5  # elements whose centroid lies within this many radii of the tunnel axis



def required_cohesion(sxx: np.ndarray, syy: np.ndarray, sxy: np.ndarray, phi_deg: float = PHI) -> np.ndarray:
    """c that puts in-plane stresses (compression negative) on the Mohr-Coulomb surface of friction
    angle phi: [(s1 - s3) + (s1 + s3) sin phi] / (2 cos phi)."""
    m, r = 0.5 * (sxx + syy), np.hypot(0.5 * (sxx - syy), sxy)
    s1, s3 = m + r, m - r
    phi = math.radians(phi_deg)
    return ((s1 - s3) + (s1 + s3) * math.sin(phi)) / (2 * math.cos(phi))


def screen(misfit, p_hat: np.ndarray) -> list[Hypothesis]:
    """The yielding hypotheses worth a refit at the baseline optimum (see the module docstring)."""
    sim = misfit.simulation
    case = sim.loaded.case
    openings = hasattr(case.geometry, "openings")  # (linings there are bands, modelled on yielding ground)
    if getattr(sim, "piecewise_smooth", False) or (not openings and case.construction is not None
                                                   and case.construction.lining):
        return []
    values = misfit.values(p_hat)
    if any(n.startswith("zoff[") for n in misfit.parameters.names) or sim.survey.offsets(values):
        return []  # the elastoplastic simulation does not read inclinometers at depth offsets
    if any(k.split("[", 1)[0] in ("n", "m") and float(v) != 1.0 for k, v in values.items()):
        return []  # ... nor cross-anisotropic ground (an anisotropy accepted in an earlier round)
    if openings:
        mesh, near, c_req = _section_screen(sim, values)
    else:
        fld = sim.field(values)
        mesh, cell = fld.mesh, fld.cell_data
        g = case.geometry
        centroid = mesh.nodes[mesh.triangles[:, :3]].mean(axis=1)
        near = np.hypot(centroid[:, 0], centroid[:, 1] + g.axis_depth) < SCREEN_RADIUS * g.radius
        c_req = required_cohesion(cell["stress_xx"], cell["stress_yy"], cell["stress_xy"])
    out = []
    where = "excavation" if openings else "tunnel"  # a section's openings: a box, a heading and bench
    for i, layer in enumerate(case.ground.layers):
        sel = near & (mesh.region == i)
        if not sel.any():
            continue
        c_crit = float(c_req[sel].max())
        E = float(values[f"E[{layer.name}]"])
        weakest = E / STIFFNESS_TO_STRENGTH
        if c_crit <= weakest:
            continue
        c0 = c_crit / MARGIN
        name = layer.name
        several = sum(1 for j in range(len(case.ground.layers)) if (near & (mesh.region == j)).any()) > 1
        out.append(Hypothesis(
            f"yielding[{name}]", "yielding",
            f"the ground yields around the {where}" + (f" ('{name}')" if several else "")
            + f" (Mohr-Coulomb, phi' = {PHI:g} deg and psi = {PSI:g} deg assumed)",
            f"The ground of '{name}' yields around the {where} (Mohr-Coulomb, phi' = {PHI:g} deg and psi = {PSI:g} deg "
            f"fixed, c' identified). At the elastic fit its stresses near the {where} would need c' of at least "
            f"{c_crit:.3g} kPa to stay elastic, above the {weakest:.3g} kPa of the weakest plausible ground of "
            f"E = {E:.4g} kPa (E/c = {STIFFNESS_TO_STRENGTH:g}); the refit starts from c' = {c0:.3g} kPa (a plastic "
            f"zone {'at the wall' if where == 'tunnel' else 'beside the opening'}) and is tested by likelihood ratio "
            f"(no score test: at an elastic state every sensitivity to the strength is zero).",
            [Parameter(name=f"c[{name}]", initial=c0, bounds=(c_crit / 200, 2 * c_crit), log=True)]))
    return out


def _section_screen(sim, values) -> tuple:
    """With openings: (mesh, near, c_req) over the ground of the section, `near` the elements within
    (SCREEN_RADIUS - 1) equivalent radii of an opening's wall (as within SCREEN_RADIUS R of a circular
    tunnel's axis) that are ground when read, c_req the largest cohesion their stress asks for over
    the stages (a heading released before its support may yield before the lining acts)."""
    from shapely import distance, points

    from geoback.case.layout import polygon

    case, mesh = sim.loaded.case, sim.mesh
    centroid = mesh.nodes[mesh.triangles[:, :3]].mean(axis=1)
    pts = points(centroid[:, 0], centroid[:, 1])
    near = np.zeros(len(centroid), bool)
    for op in case.geometry.openings:
        poly = polygon(op)
        near |= distance(poly, pts) < (SCREEN_RADIUS - 1) * math.sqrt(poly.area / math.pi)
    ground = getattr(mesh, "band", np.full(len(centroid), -1)) < 0  # linings are not the ground that yields
    c_req = np.full(len(centroid), -np.inf)
    for k in range(len(sim.stages)):
        stress = sim.element_stress(values, k)  # NaN where the stage has removed the element
        c_k = required_cohesion(stress[:, 0], stress[:, 1], stress[:, 2])
        c_req = np.fmax(c_req, np.where(np.isfinite(c_k), c_k, -np.inf))
    return mesh, near & ground & np.isfinite(c_req), c_req


def refit(h: Hypothesis, current, cur_fit, settings, method: str, say):
    """The baseline with the hypothesis' layer made mohr-coulomb, fitted; a procedure.Scored with its
    likelihood-ratio test (score and its p-value are NaN: there is none), or None if the yielding
    model cannot be solved from its start."""
    spec = h.parameters[0]
    best = None
    for factor in START_FACTORS:  # the better of the starts (a wider zone first: see START_FACTORS)
        s = _fit_from(h, current, cur_fit, settings, method, say, spec.initial * factor)
        if s is not None and (best is None or s.refit.J < best.refit.J):
            best = s
    if best is None:
        return None
    J0 = lr_objective(current, cur_fit)
    compare(best, J0, 0)
    if _stalled(best):  # a continuation start: a wider zone still, from which the fit can shrink it
        say(f"  the refit stalled (c' {best.refit.p[-1]:.3g} kPa, at the elastic end or no better than the "
            f"elastic fit): again from a wider plastic zone")
        again = _fit_from(h, current, cur_fit, settings, method, say, spec.initial * CONTINUATION)
        if again is not None:
            compare(again, J0, 0)
            if again.refit.J < best.refit.J:
                best = again
    if best.settled and best.dJ > 0:  # the friction angle freed where the cohesion is determined
        judge(best)
        if best.determined:
            free = _fit_phi(h, best, current, settings, method, say)
            if free is not None:
                compare(free, J0, 0)
                judge(free)
                if free.settled and free.determined and free.aic < best.aic:
                    best = free
    return best


CONTINUATION = 0.2  # the continuation start's cohesion, a fraction of the screen's start
PHI_RANGE = (15.0, 45.0)  # degrees: the friction angle's search range when it is freed


def _stalled(s: Scored) -> bool:
    """A refit that walked c' to the elastic end of its range (every gradient in c' zero there) or
    ended no better than the elastic fit."""
    spec = s.hypothesis.parameters[0]
    c = float(s.refit.p[-1])
    return (not s.settled) or s.dJ <= 0 or c >= 0.98 * spec.bounds[1]


def _mohr_coulomb_misfit(h, current, cur_fit, c0: float, specs: list, start: np.ndarray):
    """The current model with the hypothesis' layer made mohr-coulomb (c0, PHI, PSI), `specs` identified."""
    layer = h.key[len("yielding["):-1]
    return _with_layer(current, layer, {"model": "mohr-coulomb", "c": c0, "phi": PHI, "psi": PSI}, specs, start)


def with_angles(misfit, layer: str, phi: float, psi: float, start: np.ndarray):
    """The same model and parameters with the layer's phi' and psi set in its case (the amended case
    carries them), started from `start`."""
    return _with_layer(misfit, layer, {"phi": float(phi), "psi": float(psi)}, [], start)


def _with_layer(current, layer: str, update: dict, specs: list, start: np.ndarray):
    """`current` on the same mesh with the fields `update` of `layer` changed in its case (its simulation
    made yielding), `specs` identified too."""
    from geoback.physics.plastic import PlasticSimulation

    sim = current.simulation
    loaded = sim.loaded
    layers = [ly.model_copy(update=update) if ly.name == layer else ly for ly in loaded.case.ground.layers]
    case = loaded.case.model_copy(update={"ground": loaded.case.ground.model_copy(update={"layers": layers})})
    if hasattr(case.geometry, "openings"):  # yielding ground with openings (the factory's row for it)
        from geoback.physics.factory import make_simulation

        plastic = make_simulation(loaded.with_case(case), mesh=sim.mesh, blocks=list(current.data.blocks),
                                  backend=getattr(sim, "backend", None), extensions=EXTENSIONS)
    else:
        plastic = PlasticSimulation(loaded.with_case(case), mesh=sim.mesh, blocks=list(current.data.blocks),
                                    backend=getattr(sim, "backend", None), extensions=EXTENSIONS)
    values = {f"{k}[{layer}]": v for k, v in update.items() if k in ("c", "phi", "psi")
              and f"{k}[{layer}]" in current.base_values}  # a fixed value of the model as the case now says
    return current.extended(specs, values, simulation=plastic, start=start)


def _fit_from(h, current, cur_fit, settings, method, say, c0: float) -> Scored | None:
    spec = h.parameters[0]
    say(f"refitting with {h.title} (c' from {c0:.3g} kPa, phi' = {PHI:g} deg)")
    s = Scored(h, float("nan"), len(h.parameters), float("nan"))
    try:
        s.misfit = _mohr_coulomb_misfit(h, current, cur_fit, c0, [spec.model_copy(update={"initial": c0})], cur_fit.p)
        s.refit, s.reliability = fit_and_assess(s.misfit, settings, method, REFIT_ITERATIONS)
    except ForwardFailure as exc:
        say(f"  not refitted from c' = {c0:.3g} kPa: {exc}")
        return None
    return s


def _fit_phi(h, best: Scored, current, settings, method, say) -> Scored | None:
    """The refit with phi' free too, from the c' refit's optimum (phi' = PHI): the readings of a tunnel
    mostly tell the strength at the wall's confinement, and with c' determined they may tell phi'."""
    layer = h.key[len("yielding["):-1]
    c_hat = float(best.refit.p[-1])
    spec = h.parameters[0]
    phi = Parameter(name=f"phi[{layer}]", initial=PHI, bounds=PHI_RANGE)
    h2 = Hypothesis(h.key, h.kind, h.title.replace(f"phi' = {PHI:g} deg and ", ""),
                    h.description.replace(f"phi' = {PHI:g} deg and psi = {PSI:g} deg fixed, c' identified",
                                          f"c' and phi' identified, psi = {PSI:g} deg fixed"),
                    [spec.model_copy(update={"initial": c_hat}), phi], dict(h.extra_values), h.group)
    say(f"refitting with {h2.title} (phi' freed from {PHI:g} deg, c' from {c_hat:.3g} kPa)")
    s = Scored(h2, float("nan"), 2, float("nan"))
    try:
        s.misfit = _mohr_coulomb_misfit(h2, current, None, c_hat, h2.parameters, best.refit.p[:-1])
        s.refit, s.reliability = fit_and_assess(s.misfit, settings, method, REFIT_ITERATIONS)
    except ForwardFailure as exc:
        say(f"  phi' not freed: {exc}")
        return None
    return s


# ---------------------------------------------------------------------------- the strength determined
PROFILE_PHI = (20.0, 25.0, 30.0, 35.0, 40.0)  # degrees: phi' held at each in turn (step 3 of the docstring)
PROFILE_PSI = (0.0, 5.0, 10.0)  # degrees: psi held at each: from no volume change in shear (clays) to that of
# dense sands (psi ~ phi' - 30 deg); a tunnel's readings hardly tell psi, and c' moves with it (measured on
# cases/concealed/yielding.yaml: c' 42.8 kPa at psi = 0 and 44.3 at psi = 5 with phi' = 28 deg, J 55.1 and 52.6)
CHI2_1_95 = 3.841458820694124  # chi^2_1 at 95 % (inference.profile.CHI2_1_95, without loading scipy.optimize)
ADOPT = 9.210340371976182  # chi^2_2 at 1 %: the grid's best angles lower J by more than this -> the final model
# takes them (two angles chosen; at the structure checks' level, a change of the model must be a strong finding)
FINE = 0.25  # degrees: the step at which J(phi') is interpolated between the grid's angles


def unconfined_strength(c, phi_deg):
    """s_c = 2 c cos phi / (1 - sin phi), phi in degrees (physics/plasticity/closed_form.unconfined_strength)."""
    from geoback.physics.plasticity.closed_form import unconfined_strength as s_c

    return s_c(np.asarray(c, float), np.radians(phi_deg))


@dataclass(frozen=True)
class StrengthPoint:
    phi: float  # degrees, held
    psi: float  # degrees, held
    J: float  # the fit's objective there
    c: float  # kPa, c' fitted there
    log_std: float  # linearised std of ln c' there
    p: tuple = ()  # the fit's parameters there (the final model's order)


@dataclass(frozen=True)
class StrengthProfile:
    """What the readings determine of a yielding layer's strength with phi' and psi not assumed (step 3 of
    the module docstring): 95 % intervals of c', s_c and phi' with phi' and psi profiled over `points`."""
    layer: str
    points: tuple  # StrengthPoint, by psi then phi
    c_low: float
    c_high: float
    ucs_low: float
    ucs_high: float
    phi_low: float
    phi_high: float
    phi_open: tuple  # (low end open, high end open): J still within 3.84 at the last angle fitted there
    best: tuple  # (phi, psi) of the lowest J
    seconds: float
    assumed: tuple = (PHI, PSI)  # the angles of the final model: PHI, PSI, or those adopted (ADOPT)

    @property
    def phi_grid(self) -> tuple:
        return min(p.phi for p in self.points), max(p.phi for p in self.points)

    @property
    def psi_grid(self) -> tuple:
        return min(p.psi for p in self.points), max(p.psi for p in self.points)

    @property
    def assumed_J(self) -> float:
        return next(p.J for p in self.points if (p.phi, p.psi) == self.assumed)

    @property
    def adopted(self) -> bool:
        return self.assumed != (PHI, PSI)

    @property
    def to_adopt(self) -> bool:
        """The grid's best angles fit the readings better than the assumed ones by more than ADOPT."""
        return not self.adopted and self.gain > ADOPT

    @property
    def gain(self) -> float:
        """How much lower J is at the best angles of the grid than at the assumed ones."""
        return self.assumed_J - min(p.J for p in self.points)

    def J_of(self, phi: float, psi: float) -> float:
        return next(p.J for p in self.points if (p.phi, p.psi) == (phi, psi))

    def interval(self, low: float, high: float) -> tuple[float, float]:
        """c' 95 % with phi' and psi profiled out, from the interval (low, high) at the assumed angles: their
        union where the assumed angles lie inside the 95 % region (its slice there is part of it), else the
        profile's alone (the assumed angles' interval is then relative to a J the readings reject)."""
        if self.gain > CHI2_1_95:
            return self.c_low, self.c_high
        return min(low, self.c_low), max(high, self.c_high)

    def angles_words(self) -> str:
        """What the readings say of the assumed angles: '' where they are within the 95 % region."""
        if self.adopted:
            (phi, psi), rejected = self.assumed, self.J_of(PHI, PSI) - self.assumed_J
            return (f"the final model takes phi' = {phi:g} and psi = {psi:g} deg, the angles the readings favour: "
                    f"with the assumed {PHI:g} and {PSI:g} deg J was higher by {rejected:.4g} (more than the "
                    f"{ADOPT:.3g} of chi^2 with 2 degrees of freedom at 1 %)")
        if self.gain <= CHI2_1_95:
            return ""
        here = next(p.c for p in self.points if (p.phi, p.psi) == (PHI, PSI))
        return (f"the readings favour phi' = {self.best[0]:g} and psi = {self.best[1]:g} deg over the assumed {PHI:g} "
                f"and {PSI:g} deg (J lower by {self.gain:.4g}, more than the 3.84 of a 95 % interval): the model with the "
                f"assumed angles leaves misfit that other angles remove, and its c' = {here:.4g} kPa is the strength "
                f"at angles the readings reject")

    def words(self) -> str:
        (lo, hi), (q0, q1) = (PROFILE_PHI[0], PROFILE_PHI[-1]), self.psi_grid
        if all(self.phi_open):
            phi = f"the readings do not bound phi' within {self.phi_low:.3g}-{self.phi_high:.3g} deg"
        elif self.phi_open[0]:
            phi = (f"the readings allow phi' up to {self.phi_high:.3g} deg, not bounded below within the "
                   f"{self.phi_low:.3g} deg fitted")
        elif self.phi_open[1]:
            phi = (f"the readings allow phi' from {self.phi_low:.3g} deg, not bounded above within the "
                   f"{self.phi_high:.3g} deg fitted")
        else:
            phi = f"the readings allow phi' {self.phi_low:.3g} to {self.phi_high:.3g} deg"
        return (f"the strength of '{self.layer}' with phi' and psi not assumed: c' 95 % [{self.c_low:.4g}, "
                f"{self.c_high:.4g}] kPa and the unconfined strength 2c' cos phi' / (1 - sin phi') 95 % "
                f"[{self.ucs_low:.4g}, {self.ucs_high:.4g}] kPa for phi' anywhere in {lo:g}-{hi:g} deg and psi in "
                f"{q0:g}-{q1:g} deg ({phi}; profile likelihood, {len(self.points)} fits with phi' and psi held, "
                f"{self.seconds:.1f} s)" + (f"; {self.angles_words()}" if self.angles_words() else ""))

    def as_dict(self) -> dict:
        return {"layer": self.layer, "phi_range_deg": list(self.phi_grid), "psi_range_deg": list(self.psi_grid),
                "ci95_c_kPa": [self.c_low, self.c_high], "ci95_unconfined_strength_kPa": [self.ucs_low, self.ucs_high],
                "ci95_phi_deg": [self.phi_low, self.phi_high], "ci95_phi_open": list(self.phi_open),
                "best_phi_psi_deg": list(self.best), "J_lower_at_best_than_assumed": self.gain,
                "assumed_angles_rejected": self.gain > CHI2_1_95 or self.adopted,
                "final_model_phi_psi_deg": list(self.assumed), "adopted": self.adopted,
                "points": [{"phi_deg": p.phi, "psi_deg": p.psi, "J": p.J, "c_kPa": p.c, "c_log_std": p.log_std}
                           for p in self.points],
                "seconds": self.seconds,
                "how": "phi' and psi held at each point of the grid, c' and the other parameters fitted; 95 % "
                       "profile likelihood with phi' and psi profiled out (J interpolated in phi' by a cubic "
                       "spline, each slice linearised in ln c')"}


def _slice(points) -> tuple:
    """One psi's fitted angles interpolated every FINE degrees: (phi, J, ln c', std of ln c'); J by a cubic
    spline (a parabola through three angles: linear interpolation would overstate J between them and
    narrow the intervals), ln c' and its std linearly."""
    from scipy.interpolate import CubicSpline

    pts = sorted(points, key=lambda q: q.phi)
    phi_k = np.array([q.phi for q in pts])
    J_k = np.array([q.J for q in pts])
    phi = np.unique(np.concatenate([np.arange(phi_k[0], phi_k[-1], FINE), phi_k]))
    J = CubicSpline(phi_k, J_k)(phi) if len(pts) >= 3 else np.interp(phi, phi_k, J_k)
    lc = np.interp(phi, phi_k, [math.log(q.c) for q in pts])
    sd = np.interp(phi, phi_k, [q.log_std for q in pts])
    return phi, J, lc, sd


def combine(points, layer: str, seconds: float = 0.0) -> StrengthProfile:
    """The profile's intervals from the fitted points (step 3 of the module docstring): per psi, J(phi'),
    ln c' and its std interpolated (``_slice``); c' with phi' and psi profiled out is the union over them
    of exp(ln c' +- sqrt(3.84 - (J - J_min)) std), J_min the lowest over every slice. An end of phi'
    still within 3.84 at the last angle fitted on that side (the grid's end, or the last the model
    could be solved at) is open."""
    slices = [_slice([q for q in points if q.psi == psi]) for psi in sorted({q.psi for q in points})]
    Jmin = min(float(J.min()) for _, J, _, _ in slices)
    c_lo, c_hi, u_lo, u_hi, allowed, open_lo, open_hi = [], [], [], [], [], False, False
    for phi, J, lc, sd in slices:
        budget = CHI2_1_95 - (J - Jmin)
        inside = budget >= 0
        if not inside.any():
            continue
        half = np.sqrt(budget[inside]) * sd[inside]
        lo, hi = np.exp(lc[inside] - half), np.exp(lc[inside] + half)
        c_lo.append(lo.min()), c_hi.append(hi.max())
        u_lo.append(unconfined_strength(lo, phi[inside]).min()), u_hi.append(unconfined_strength(hi, phi[inside]).max())
        allowed.append(phi[inside])
        open_lo, open_hi = open_lo or bool(inside[0]), open_hi or bool(inside[-1])
    allowed = np.concatenate(allowed)
    best = min(points, key=lambda q: q.J)
    return StrengthProfile(layer, tuple(sorted(points, key=lambda q: (q.psi, q.phi))), float(min(c_lo)),
                           float(max(c_hi)), float(min(u_lo)), float(max(u_hi)), float(allowed.min()),
                           float(allowed.max()), (open_lo, open_hi), (best.phi, best.psi), seconds)


def strength_profile(layer: str, misfit, result, settings, method: str, say) -> StrengthProfile | None:
    """Step 3 of the module docstring on a fitted model (`misfit`, its Fit `result`; the layer's phi' and
    psi fixed in its case, at PHI and PSI or at angles adopted from the grid; c[layer] a parameter); None
    where phi' or psi is a parameter or the fit did not converge. Per psi, outwards from PHI in each
    direction, each fit started from its neighbour's optimum (the first of a psi from PHI at the previous
    psi) with s_c kept."""
    from geoback.inference.estimate import fit
    from geoback.inference.reliability import assess

    names = list(misfit.parameters.names)
    if (f"phi[{layer}]" in names or f"psi[{layer}]" in names or f"c[{layer}]" not in names
            or result.status != "converged"):
        return None
    t0 = time.perf_counter()
    ic = names.index(f"c[{layer}]")
    ext = misfit.extended([Parameter(name=f"phi[{layer}]", initial=PHI, bounds=PHI_RANGE),
                           Parameter(name=f"psi[{layer}]", initial=PSI, bounds=(0.0, PHI_RANGE[1]))], start=result.p)
    iphi = list(ext.parameters.names).index(f"phi[{layer}]")
    rel = assess(misfit.evaluate(result.p, jacobian=True), misfit.parameters, misfit.logdet)
    values = misfit.values(result.p)
    model_angles = (float(values[f"phi[{layer}]"]), float(values[f"psi[{layer}]"]))
    here = StrengthPoint(*model_angles, float(result.J), float(result.p[ic]), float(rel.std[ic]) / float(result.p[ic]),
                         tuple(map(float, result.p)))
    centre, p_centre = here, np.asarray(result.p, float)
    done = {model_angles: (here, p_centre)}  # each point of the grid fitted once (the model's own angles: the fit)

    def held_fit(phi, psi, prev, p_prev):
        """The fit with phi' and psi held, from `prev` (its parameters p_prev) with s_c kept; None if unsolvable."""
        if (phi, psi) in done:
            return done[(phi, psi)]
        say(f"the strength with phi' = {phi:g} and psi = {psi:g} deg held (c' and the other parameters fitted)")
        start = p_prev.copy()
        start[ic] = prev.c * float(unconfined_strength(1.0, prev.phi) / unconfined_strength(1.0, phi))
        held = ext.holding(iphi + 1, psi).holding(iphi, phi)
        try:
            f = fit(held, settings, method=method, p0=start)
            rel = assess(held.evaluate(f.p, jacobian=True), held.parameters, held.logdet)
        except ForwardFailure as exc:
            say(f"  not solved there: {exc}")
            return None
        c = float(f.p[ic])
        done[(phi, psi)] = (StrengthPoint(phi, psi, float(f.J), c, float(rel.std[ic]) / c, tuple(map(float, f.p))),
                            np.asarray(f.p, float))
        return done[(phi, psi)]

    for psi in PROFILE_PSI:
        got = held_fit(PHI, psi, centre, p_centre)
        if got is None:
            break
        centre, p_centre = got
        for angles in ([a for a in reversed(PROFILE_PHI) if a < PHI], [a for a in PROFILE_PHI if a > PHI]):
            got = (centre, p_centre)
            for phi in angles:
                got = held_fit(phi, psi, *got) if psi <= phi else None
                if got is None:
                    break
                if got[0].J - centre.J > CHI2_1_95 and got[0].J > centre.J:  # farther angles lie outside as well
                    break
    return replace(combine([q for q, _ in done.values()], layer, time.perf_counter() - t0), assumed=model_angles)


def adopt(profile: StrengthProfile, misfit, settings, method: str, say):
    """Step 4 of the module docstring: (the model with the angles the readings favour, its Fit, the profile
    with them as its model's), or None where it cannot be solved or does not fit better than the assumed
    angles by more than ADOPT."""
    from geoback.inference.estimate import fit

    best = next(q for q in profile.points if (q.phi, q.psi) == profile.best)
    say(f"the final model with phi' = {best.phi:g} and psi = {best.psi:g} deg, the angles the readings favour")
    try:
        m = with_angles(misfit, profile.layer, best.phi, best.psi, np.asarray(best.p, float))
        f = fit(m, settings, method=method, p0=np.asarray(best.p, float))
    except ForwardFailure as exc:
        say(f"  not solved: {exc}")
        return None
    if f.status != "converged" or not f.J < profile.assumed_J - ADOPT:
        return None
    return m, f, replace(profile, assumed=profile.best)


def adopted_title(title: str, profile: StrengthProfile | None) -> str:
    """A yielding cause's title with the angles its final model takes."""
    if profile is None or not profile.adopted:
        return title
    phi, psi = profile.assumed
    return title.replace(f"phi' = {PHI:g} deg and psi = {PSI:g} deg assumed",
                         f"phi' = {phi:g} deg and psi = {psi:g} deg, the angles the readings favour")
