"""Hypothesis 'the tunnel was supported before the full release', the rival family a one-step model
lacks (issue 24): an engineer who models a lined tunnel as a one-step excavation (as the paper's own
example does) leaves out that the ground took only a fraction beta of the in-situ stress before a
support acted, the rest being carried by ground and support together. Without this family in the
library such readings are explained by whatever else bends the displacement field (a stiffer stratum,
a gradient), confidently and wrongly.

The extended model is the staged model of the case (``case/construction.py``, ``physics/staged.py``):
stage 'advance' releases beta on the ground alone, then a lining of assumed properties (shotcrete,
SHOTCRETE_E, thickness a tenth of the radius up to MAX_THICKNESS) is installed and the last stage
(the case's single stage, so that the readings keep their stage) releases the rest on ground and
lining together. beta is identified with the baseline's parameters from beta = 1 (the null value: the
lining installed after the full release carries nothing, the model is the one-step model), the
lining's modulus held at its assumed value (at beta = 1 it is not identifiable, and between a stiffer
lining and a smaller beta the readings mostly tell the product). Like yielding (``yielding.py``) it
is refitted whenever the model is not adequate and tested by likelihood ratio (null on the boundary
beta = 1: the chi^2(1) reference is conservative), in the same Bonferroni family.

Proposed only for a circular tunnel without a construction section, without a release parameter
already (``stress-release``'s beta), with linear-elastic ground and no inclinometer read at a depth
offset (the staged simulation does not read them).
"""
from __future__ import annotations

from geoback.case.loading import Parameter
from geoback.errors import ForwardFailure, GeobackError
from geoback.diagnosis.hypotheses import Hypothesis
from geoback.diagnosis.refit import REFIT_ITERATIONS, compare, fit_and_assess, lr_objective, null_start
from geoback.diagnosis.results import Scored

SHOTCRETE_E = 10.0e6  # kPa: young-to-mature shotcrete (2-30 GPa)
MAX_THICKNESS = 0.3  # m
BETA = "beta[advance]"


def propose(misfit, p_hat) -> list[Hypothesis]:
    """The hypothesis when it applies to the misfit's model (module docstring)."""
    sim = misfit.simulation
    case = sim.loaded.case
    if (hasattr(case.geometry, "openings") or case.construction is not None or getattr(sim, "piecewise_smooth", False)
            or any(n == "beta" or n.startswith("beta[") for n in misfit.parameters.names)
            or any(getattr(ly, "model", "linear-elastic") != "linear-elastic" for ly in case.ground.layers)):
        return []
    if any(n.startswith("zoff[") for n in misfit.parameters.names) or sim.survey.offsets(misfit.values(p_hat)):
        return []  # the staged simulation does not read inclinometers at depth offsets
    t = round(min(MAX_THICKNESS, 0.1 * case.geometry.radius), 3)
    return [Hypothesis(
        "supported-release", "supported-release", "the tunnel was supported before the full release",
        f"The ground took only a fraction beta of the in-situ stress before a support acted (a lining of "
        f"{t:g} m shotcrete, E = {SHOTCRETE_E / 1e6:g} GPa assumed); ground and support carried the rest together "
        f"(convergence-confinement; the one-step model releases everything on the ground alone).",
        [Parameter(name=BETA, initial=1.0, bounds=(0.05, 1.0))], {"thickness": t})]


def _supported_case(case, thickness: float):
    from geoback.case.construction import DEFAULT_STAGE

    construction = {"lining": {"name": "support", "thickness": thickness, "E": SHOTCRETE_E, "nu": 0.2},
                    "stages": [{"name": "advance", "release": 0.99},
                               {"name": DEFAULT_STAGE, "install": "support", "release": 1.0}]}
    from geoback.case.schema import Construction

    return case.model_copy(update={"construction": Construction.model_validate(construction)})


def refit(h: Hypothesis, current, cur_fit, settings, method: str, say) -> Scored | None:
    """The staged model with beta free, fitted from the null (beta = 1) at the current optimum; a
    Scored with its likelihood-ratio test (no score: NaN), or None if the model cannot be built."""
    from geoback.physics.factory import make_simulation

    sim = current.simulation
    loaded = sim.loaded
    say(f"refitting with {h.title}")
    s = Scored(h, float("nan"), len(h.parameters), float("nan"))
    try:
        case = _supported_case(loaded.case, h.extra_values["thickness"])
        staged = make_simulation(loaded.with_case(case), mesh=sim.mesh, blocks=list(current.data.blocks),
                                 backend=getattr(sim, "backend", None))
        s.misfit = current.extended(h.parameters, simulation=staged, start=cur_fit.p)
        null = null_start(s.misfit)
        ev = s.misfit.evaluate(null)
        J_null = float(ev.support) if s.misfit.free else float(ev.J)
        s.refit, s.reliability = fit_and_assess(s.misfit, settings, method, REFIT_ITERATIONS, starts=[null])
    except (ForwardFailure, GeobackError) as exc:
        say(f"  not refitted: {exc}")
        return None
    compare(s, lr_objective(current, cur_fit), 0, J_null=J_null)
    return s
