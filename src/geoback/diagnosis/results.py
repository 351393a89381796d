"""What `diagnose` finds, as data: a located mismatch, a scored (and refitted) hypothesis, a round,
the whole diagnosis (read by diagnosis/report.py; built by diagnosis/procedure.py)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from geoback.inference.estimate import Fit
from geoback.inference.identification import Identification
from geoback.inference.misfit import Misfit
from geoback.inference.reliability import Reliability
from geoback.diagnosis.depth import DepthProfile
from geoback.diagnosis.hypotheses import Hypothesis


@dataclass
class Mismatch:
    instrument: str
    kind: str
    share: float  # of J
    where: str  # plain words, e.g. "6-9 m depth"
    size: float  # displacement mismatch over the stretch [m] (measured - computed)
    sigmas: float  # its significance in standard deviations
    text: str


@dataclass
class Scored:
    hypothesis: Hypothesis
    score: float
    dof: int
    p_score: float
    collinear_with: str | None = None  # combination of baseline parameters it duplicates
    refit: Fit | None = None
    reliability: Reliability | None = None
    J0: float = float("nan")
    dJ: float = float("nan")
    p_lr: float = float("nan")
    aic: float = float("nan")
    bic: float = float("nan")
    misfit: Misfit | None = None  # the baseline extended with the hypothesis
    m2: np.ndarray | None = None  # per extra parameter (a column each): the whitened sensitivity the baseline
    # cannot mimic; the correlation of two hypotheses' score statistics under the null is that of their columns
    detectable: dict = field(default_factory=dict)  # parameter -> |change| the score test catches with 80 %
    determined: bool = True  # the readings determine every extra parameter of the refit (caveats.py)
    caveats: list = field(default_factory=list)  # the refit's caveats on its extra parameters
    profile: DepthProfile | None = None  # a layer boundary's depth profile
    weight: float = float("nan")  # Akaike weight in its round
    group_size: int = 1  # hypotheses of its group (a layer boundary's depths): p_score is Bonferroni over them
    p_single: float = float("nan")  # the score test's p of this one hypothesis (before the group's Bonferroni)
    worse: bool = False  # the refit ended above the model it extends: no improvement (refit.compare)
    at_bound: dict = field(default_factory=dict)  # extra parameter -> 'lower' | 'upper': left on a search bound
    grade: str = ""  # an accepted hypothesis: 'named' or 'explained' (GRADES; claims.py)
    checks: dict = field(default_factory=dict)  # the claim checks: name -> claims.Check
    rivals: list = field(default_factory=list)  # refits of other families that explain the readings as well
    separations: dict = field(default_factory=dict)  # rival's key -> compare.Separation: where its predictions and
    # this cause's differ most (existing readings, instruments, new points): what would tell the two apart

    @property
    def m2_norms(self) -> np.ndarray | None:
        """The norm of each extra parameter's column of ``m2`` (what its score test can see of it)."""
        return None if self.m2 is None else np.linalg.norm(self.m2, axis=0)

    @property
    def settled(self) -> bool:
        """Refitted, converged (or stalled) and no worse than the model it extends."""
        return self.refit is not None and settled(self.refit) and not self.worse

    @property
    def family(self) -> str:
        return family_of(self.hypothesis.kind)

    def tested_as(self, other: "Scored") -> "Scored":
        """This refit takes the score test of `other` (the row of its group it replaces): p, the
        group's size and the single depth's p."""
        self.p_score, self.group_size, self.p_single = other.p_score, other.group_size, other.p_single
        return self


@dataclass
class Round:
    chi2: float
    dof: int
    p_value: float
    mismatches: list[Mismatch]
    ranking: list[Scored]
    accepted: Scored | None
    adequate: bool = False  # chi^2 test passed and no hypothesis' score test is significant
    threshold: float = float("nan")  # per-hypothesis level alpha / K (Bonferroni over the library)
    scales: list = field(default_factory=list)  # scales.ScaleEstimate of every group at this round's fit
    scale_threshold: float = float("nan")  # per-scale level alpha / G (Bonferroni over the estimated scales)
    aic: float = float("nan")  # of the round's model (no hypothesis added)
    weights: dict = field(default_factory=dict)  # Akaike weights: hypothesis key (or NO_ADDITION) -> weight
    rival: Scored | None = None  # a hypothesis within 2 AIC of the accepted one, else its closest rival of another
    # family within the evidence (check 3; all of them: the accepted one's ``rivals``)
    separation: object = None  # compare.Separation of the accepted one and this rival
    tentative: bool = False  # accepted although an extra parameter is not determined
    hypotheses: int = 0  # hypotheses scored (every depth of a layer boundary counted)
    screened: int = 0  # hypotheses no score test can rank, refitted instead (yielding): in the family too

    @property
    def tests(self) -> int:
        """Score tests in the Bonferroni family: one per row of the ranking that can be tested (a
        layer boundary's depths are one test, Bonferroni within it)."""
        return sum(1 for s in self.ranking if s.collinear_with is None and s.hypothesis.kind not in SCREENED)

    @property
    def family(self) -> int:
        """The Bonferroni family: the score tests and the screened hypotheses (threshold = alpha / family)."""
        return self.tests + self.screened

    def family_words(self, alpha: float) -> str:
        """What the level counts: '0.05 / 15: 14 score tests (one per row; the 25 depths of a layer
        boundary in 'clay' one test) and 1 hypothesis screened by refit (yielding)'."""
        groups = [s for s in self.ranking if s.group_size > 1]
        inner = [f"the {s.group_size} depths of a layer boundary in '{s.hypothesis.group.split('[', 1)[1][:-1]}' "
                 f"are one test" for s in groups]
        untested = sum(1 for s in self.ranking if s.collinear_with is not None)
        if untested:
            inner.append(f"{untested} row{'s are' if untested > 1 else ' is'} no test: its effect is that of the "
                         f"fitted parameters")
        text = f"{alpha:g} / {self.family}: {self.tests} score test{'s' if self.tests != 1 else ''} (one per row"
        text += "".join(f"; {w}" for w in inner) + ")"
        if self.screened:
            text += (f" and {self.screened} hypothes{'es' if self.screened > 1 else 'is'} screened and refitted "
                     f"instead (no score test: yielding, a support before the full release)")
        return text


NO_ADDITION = "(no addition)"
SCREENED = frozenset({"yielding", "supported-release"})  # kinds tested by a refit only, no score test

# The grades of a verdict (issue 24): a cause that passes its claim checks is named; one that improves
# the fit but fails a check (or has a rival of another family within the evidence) is explained but not
# singled out; with nothing accepted, no effect the library can detect.
GRADES = {"named": "named", "explained": "explained but not singled out",
          "none": "no effect the library can detect"}
# Families: what a rival must differ in to make a cause not singled out. The release kinds are one family
# (a release fraction, with or without a support); a modulus gradient and a stratum are one (the ground
# stiffer or softer with depth: linear or in a step, told apart by AIC as before); every other kind is its own.
FAMILIES = {"stress-release": "release", "release-before-lining": "release", "supported-release": "release",
            "stiffness-gradient": "stiffness-with-depth", "layer-boundary": "stiffness-with-depth"}


def family_of(kind: str) -> str:
    return FAMILIES.get(kind, kind)


@dataclass
class Diagnosis:
    case: str
    alpha: float
    rounds: list[Round]
    baseline: Identification  # the case's model fitted
    final: Identification  # the model with every accepted extension, fitted
    final_misfit: Misfit
    accepted: list[Scored] = field(default_factory=list)
    final_profiles: dict = field(default_factory=dict)  # key -> DepthProfile re-profiled in the final model
    seconds: float = float("nan")
    final_intervals: dict = field(default_factory=dict)  # name -> (low, high, low open, high open): profile-
    # likelihood intervals of accepted parameters the final identification did not profile (at a bound)
    loaded: object = None  # the LoadedCase diagnosed (for the amended case: its file, its readings files)
    method: str = "lm"  # the estimation method of every fit
    not_applicable: list = field(default_factory=list)  # (kind, why) of the catalogue's rows this model cannot take
    strength: dict = field(default_factory=dict)  # key -> yielding.StrengthProfile: an accepted yielding cause's
    # strength with phi' and psi profiled out (its c' interval is the estimates' one)

    @property
    def baseline_fit(self) -> Fit:
        return self.baseline.fit

    @property
    def baseline_reliability(self) -> Reliability:
        return self.baseline.reliability

    @property
    def final_fit(self) -> Fit:
        return self.final.fit

    @property
    def final_reliability(self) -> Reliability:
        return self.final.reliability

    @property
    def adequate_before(self) -> bool:
        return self.rounds[0].adequate

    @property
    def adequate_after(self) -> bool:
        return self.rounds[-1].adequate

    def estimates(self, s: Scored) -> list[tuple[str, float, float, float, float]]:
        """(name, estimate, std, 95 % low, 95 % high) of an accepted hypothesis' parameters from the
        FINAL joint fit (profile-likelihood intervals where the linearised ones are unreliable; a
        profiled boundary's modulus with its depth profiled out too; a yielding layer's c' with its
        phi' profiled out too: ``strength``)."""
        fin = self.final
        lo, hi = fin.intervals95()
        names = list(fin.parameters.names)
        prof = self.depth_profile(s)
        strength = self.strength.get(s.hypothesis.key)
        out = []
        for name in s.hypothesis.names:
            if name not in names:
                continue
            i = names.index(name)
            a, b = float(lo[i]), float(hi[i])
            if name in self.final_intervals:
                a, b = self.final_intervals[name][:2]
            if prof is not None:
                a2, b2 = prof.modulus_interval(name, (a, b))
                a, b = min(a, a2), max(b, b2)
            if strength is not None and name == f"c[{strength.layer}]":  # phi' and psi profiled out, not assumed
                a, b = strength.interval(a, b)
            out.append((name, float(self.final_fit.p[i]), float(fin.reliability.std[i]), a, b))
        return out

    def round_of(self, s: Scored) -> Round | None:
        """The round in which `s` was accepted."""
        return next((r for r in self.rounds if r.accepted is s), None)

    def selective(self, s: Scored) -> dict:
        """name -> selection.SelectiveInterval of an accepted cause with one extra parameter whose
        likelihood-ratio test is the regular one (not a screened kind, not one of a searched group): its 95 %
        interval (final joint fit) allowing for its acceptance on its refit's dJ at its round's level
        (``selection.py``); {} for the others."""
        from geoback.diagnosis.selection import selective_interval

        rnd = self.round_of(s)
        if (rnd is None or len(s.hypothesis.parameters) != 1 or s.hypothesis.kind in SCREENED
                or s.hypothesis.group or s.profile is not None or not np.isfinite(rnd.threshold)):
            return {}
        q = s.hypothesis.parameters[0]
        for name, v, _, lo, hi in self.estimates(s):
            if name == q.name:
                got = selective_interval(v, lo, hi, s.dJ, float(q.initial), rnd.threshold)
                return {name: got} if got is not None else {}
        return {}

    def open_ends(self, name: str) -> tuple[bool, bool]:
        """Whether the 95 % interval of an accepted parameter reaches a limit the readings do not
        move it from (a profile-likelihood interval open at that end, or a limit the linearised
        one was cut at)."""
        got = self.final_intervals.get(name) or self.final.profiled.get(name)
        if got:
            return bool(got[2]), bool(got[3])
        if name in self.final.parameters.names:
            return tuple(map(bool, self.final.interval(name).open))
        return False, False

    def interface(self, s: Scored) -> dict | None:
        """For a named stratum: the part of the split layer as stiff as the case's layer next to it (the
        difference of the two moduli within its 95 % interval, from the final joint fit's covariance), so
        that the boundary found is the case's interface at another depth ('soft' reaching 15.9 m rather than
        the 10 m stated): {part ('upper' or 'lower'), layer, neighbour, z, stated (the case's interface),
        E, E_neighbour, half_width (of the difference's 95 % interval)}; None otherwise."""
        prof = self.depth_profile(s)
        if prof is None or s.grade != "named" or self.loaded is None:
            return None
        layers = sorted(self.loaded.case.ground.layers, key=lambda ly: ly.top)
        names = [ly.name for ly in layers]
        if prof.layer not in names:
            return None
        i = names.index(prof.layer)
        values = self.final_misfit.values(self.final_fit.p)
        fitted = list(self.final.parameters.names)
        C = self.final_reliability.covariance

        def cov(a: str, b: str) -> float:
            return float(C[fitted.index(a), fitted.index(b)]) if a in fitted and b in fitted else 0.0

        sides = []
        if i > 0:  # the upper part like the layer above: that layer reaches deeper
            sides.append(("upper", f"E[{prof.layer}]", names[i - 1], float(layers[i].top)))
        if i + 1 < len(layers):  # the lower part like the layer below: that layer begins higher
            sides.append(("lower", f"E[{prof.layer}_below]", names[i + 1], float(layers[i + 1].top)))
        for part, mine, other, stated in sides:
            theirs = f"E[{other}]"
            if mine not in values or theirs not in values:
                continue
            var = cov(mine, mine) + cov(theirs, theirs) - 2 * cov(mine, theirs)
            if not var > 0:
                continue
            E, E_other = float(np.real(values[mine])), float(np.real(values[theirs]))
            half = 1.96 * float(np.sqrt(var))
            if abs(E - E_other) <= half:
                return dict(part=part, layer=prof.layer, neighbour=other, z=float(prof.z_hat), stated=stated,
                            E=E, E_neighbour=E_other, half_width=half)
        return None

    def depth_profile(self, s: Scored) -> DepthProfile | None:
        """The depth profile of an accepted boundary in the final model (or its round's)."""
        return self.final_profiles.get(s.hypothesis.key, s.profile)

    @property
    def grade(self) -> str:
        """'named' when every accepted cause passed its claim checks, 'explained' when one did not,
        'none' with nothing accepted (GRADES gives the words)."""
        if not self.accepted:
            return "none"
        return "named" if all(s.grade == "named" for s in self.accepted) else "explained"

    def bound_of(self, name: str) -> str | None:
        """'lower' / 'upper' when the final joint fit left parameter `name` on a search bound (not at its
        natural limit: a prop found without preload)."""
        from geoback.case.limits import natural_limit
        from geoback.inference.parameters import parameter_limits

        params = self.final.parameters
        if name not in params.names:
            return None
        i = params.names.index(name)
        if not bool(self.final_fit.at_bound[i]):
            return None
        p = self.final_fit.p[i]
        sim = self.final_misfit.simulation
        if natural_limit(parameter_limits(sim, name, self.final_misfit.values(self.final_fit.p)), p):
            return None
        return "lower" if abs(p - params.lower[i]) <= abs(p - params.upper[i]) else "upper"

    @property
    def causes(self) -> dict[str, list[Scored]]:
        """The accepted hypotheses by cause: 'instrument' and 'ground'."""
        out = {"instrument": [], "ground": []}
        for s in self.accepted:
            out[s.hypothesis.cause].append(s)
        return out


# ---------------------------------------------------------------------------------------------


STALLED = 0.01  # a refit whose J fell by less than this in its last step has stopped moving


def settled(f: Fit) -> bool:
    """Converged, or stopped by the iteration limit while J no longer moves."""
    if f.status == "converged":
        return True
    Js = [h.J for h in f.history if h.accepted]
    return len(Js) >= 2 and Js[-2] - Js[-1] < STALLED
