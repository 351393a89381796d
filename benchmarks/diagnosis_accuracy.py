"""Accuracy of `geoback diagnose` on randomised concealed-physics cases and on null cases.

Each case is a random tunnel (radius, depth, domain, E, nu, K0), a random instrument layout
(one or two inclinometers I1[, I2] beside the tunnel, an extensometer X1 above the crown,
optionally surface settlement points S) with realistic sigma's, and - for a concealed case - one
effect of random kind and magnitude that the case's (baseline) model lacks:

  stiffness-gradient    Egrad[clay] = g, g log-uniform in (0.2, 3) x E/30 per m
  layer-boundary        a real layer 'sand' (E2/E log-uniform in (1.5, 4), same nu) below a depth
                        uniform in (axis + R + 2, axis + 12) m, meshed conforming
  anisotropy            n[clay] log-uniform in (1.1, 2)
  K0-gradient           K0grad = +-k, k log-uniform in (0.01, 0.08) per m
  integration-constant  the toe of inclinometer I1 moved: B[I1] = +-b, b log-uniform in (1, 8) mm
  stress-release        beta = 1 - d, d log-uniform in (0.05, 0.4), with a prior on E in the case
                        (std 5 % of the true E, mean drawn from N(true E, that std): without it beta
                        is not separable from E)
  bias-shift            inclinometer I1's probe has a bias shift: bias[I1] = +-b, b log-uniform in
                        (0.03, 0.5) mm/m (every slope reading off by b: the readings by b L_n)
  depth-offset          inclinometer I1 read deeper or shallower than recorded: zoff[I1] = +-d, d
                        log-uniform in (0.1, 0.6) m (shallower at most 80 % of its top station's depth)
  null                  nothing (noise only)

Opt-in (--staged N, --yielding N; default 0, drawn from streams of their own after the cases above,
which stay as they were):
  release-before-lining a random two-stage tunnel with a shotcrete lining (random_staged_case: release
                        beta before the lining, the rest on ground and lining; bedrock below; every
                        instrument read after each stage); the truth releases beta = assumed +- d,
                        d log-uniform in (0.05, 0.3)
  lining-stiffness      the same, the truth's lining E = assumed x f or / f, f log-uniform in (2, 6)
  null-staged           the same with nothing concealed (false alarms on staged, lined models)
  yielding              a tunnel as above (K0 in (0.8, 1.2), coarser mesh) whose ground is in truth
                        Mohr-Coulomb: phi' in (22, 35), psi in (0, 5) degrees, c' from Salencon's closed
                        form for a plastic zone to R_p / R uniform in (1.2, 1.7); the case is elastic
The staged kinds and yielding are ground physics; --staged N draws the three staged kinds in turn.

Causes: integration-constant, bias-shift and depth-offset are instrument error, the others ground
physics; a case is also scored by cause (instrument error / ground physics / nothing).

Readings are those of the truth on a mesh twice as fine (geoback.commands.simulate.synthetic_readings,
refine = 2) with noise drawn from each instrument's C_x (random seed); the case given to
`diagnose` describes only the baseline model (E and K0 identified). Everything is drawn from
one master seed (--seed), so the benchmark is reproducible.

Effect size (the definition the floor uses): the baseline model is fitted to the truth's
NOISE-FREE readings; effect size = sqrt(J_min) in sigma units - the part of the effect the
baseline parameters cannot absorb (sqrt of the non-centrality of chi^2 at the baseline optimum;
it also contains the baseline mesh's discretisation error, which the null cases show).
Raw movement (the issue's literal wording, printed as well): max_i |x_truth_i - x_base_i| / sigma_i,
both noise-free on the fine mesh, x_base with the true baseline values and no effect, sigma_i the
standard deviation of reading i (sqrt diag C_x).

A case's answer is the kind of the FIRST accepted hypothesis ('nothing' if none is accepted);
correct when it equals the truth kind ('integration-constant' for a moved toe). A null case is a
false alarm when anything is accepted. Floors (issue): >= 90 % correct names among concealed
cases with effect size > 3; <= 5 % false alarms on null cases; every bias-shift case with effect
size > 3 named as instrument error.

Coverage: for a correctly named case, whether the 95 % interval of each of its extra parameters
(final joint fit, as the verdict reports it) holds the truth: Egrad, E[clay_below] and the
boundary's depth (profile likelihood), n, K0grad, B[I1], beta, bias[I1], zoff[I1], and for yielding
c' and the unconfined strength 2c' cos phi' / (1 - sin phi') with phi' and psi profiled out (the truth's
phi' and psi are drawn, the refit assumes 30 and 0 deg).

    python benchmarks/diagnosis_accuracy.py [--concealed 60] [--null 30] [--staged 0] [--yielding 0]
        [--seed 2024 | --seeds 2024 2025 ...] [--workers 2] [--out benchmarks/out/diagnosis_accuracy.csv]
        [--show INDEX] [--leave-out] [--only KIND ...]

--only KIND ... diagnoses the cases of those kinds among the cases drawn (the same cases as without it, e.g.
every true stratum of several seeds). The CSV's 'boundary_seen' gives, per stratum accepted, claims check 8:
readings below : their J gain / the refit's : d |d| : z z @ depth / deepest reading.

--seeds runs one set of cases per master seed (the same counts each) and prints each seed's summary, then,
with --leave-out, the confident-wrong rate pooled over the seeds with its binomial standard error.
A yielding truth whose fine-mesh run does not converge is drawn again (another tunnel and strength,
from a stream of its own: [seed, index, 7, 2, draw], at most 5 draws; the CSV's 'draw' says which):
the benchmark measures the diagnosis, not whether a truth it made up can be solved.

Leave-one-family-out (--leave-out): every concealed case (effects from the upper half of each kind's
range, as the coverage study draws them) is diagnosed with its truth's FAMILY removed from the library
(FAMILIES, as diagnosis/results.py has them: the release kinds are one family, a modulus gradient and a
stratum another, every other kind its own), so the library cannot hold the
truth: whatever is *named* is a confident wrong cause. Printed: per kind, the cases with effect size
> 3 and how many were named (grade 'named': the verdict passed its claim checks; a library without
grades names every accepted hypothesis that is not tentative), explained but not singled out, or
nothing; the rate of confident wrong causes (issue 24: <= 5 %). The library's rows are removed by
diagnose(exclude=...) where it has the option, otherwise (older code) by taking them out of the
catalogue for the call.

Printed: one progress line per case, then the confusion matrix (rows = truth kind incl. null,
columns = named kind incl. 'nothing') for all cases, for effect size > 3 and for raw movement > 3
sigma, the accuracy above the threshold (and per effect-size band), the false-alarm rate with its
binomial standard error (and per null kind when there are staged nulls), per kind the effect size and
chi^2/dof before -> after (medians), total time and the median seconds per diagnose (the diagnose call only:
meshing and the truth's forward runs excluded). The exit status is 1 when a floor is missed.
CSV (one row per case): truth kind, its parameter and magnitude, effect size, raw movement, named
kind, correct, every accepted hypothesis, the first one's estimate, round 1's refitted hypotheses
with dJ and AIC (':NC' = refit not converged), p-value of chi^2 before, chi^2/dof before and
after, the best-scored kind of round 1, number of readings, seconds, and the case's draw.
--show INDEX reruns one case in this process and prints its diagnosis (diagnosis.md text).
Meshes go to a temporary cache (GEOBACK_CACHE), removed at the end, unless --mesh-cache is given.
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_var] = "1"  # one thread per worker process (set before numpy is imported)

import argparse  # noqa: E402
import copy  # noqa: E402
import csv  # noqa: E402
import math  # noqa: E402
import shutil  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor, as_completed  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "benchmarks" / "out" / "diagnosis_accuracy.csv"
KINDS = ["stiffness-gradient", "layer-boundary", "anisotropy", "K0-gradient", "integration-constant",
         "stress-release", "bias-shift", "depth-offset"]
INSTRUMENT_KINDS = {"integration-constant", "bias-shift", "depth-offset"}
STAGED_KINDS = ["release-before-lining", "lining-stiffness"]  # opt-in (--staged): a lined, staged tunnel
YIELDING_KINDS = ["yielding"]  # opt-in (--yielding): Mohr-Coulomb truth, elastic case
NULL_KINDS = ("null", "null-staged")  # nothing concealed (an unlined / a staged, lined tunnel)
ALL_KINDS = KINDS + STAGED_KINDS + YIELDING_KINDS
THRESHOLD = 3.0  # sigma
# --leave-out: a family is what is removed from the library with a truth kind (release kinds are one)
FAMILIES = {"stress-release": "release", "release-before-lining": "release", "supported-release": "release",
            "stiffness-gradient": "stiffness-with-depth", "layer-boundary": "stiffness-with-depth"}
FLOOR_CONFIDENT_WRONG = 0.05
FLOOR_ACCURACY, FLOOR_FALSE_ALARMS = 0.90, 0.05
COLUMNS = ["case", "kind", "parameter", "magnitude", "effect_size", "raw_movement", "named", "correct",
           "cause", "named_cause", "accepted", "tentative", "estimate", "covered", "rival", "round1", "p_before",
           "chi2dof_before", "chi2dof_after", "top_score_kind", "readings", "seconds", "R", "axis_depth", "E", "nu",
           "K0", "layout", "noise_seed", "seed", "draw", "grade", "failed_checks", "left_out", "adequate_after",
           "p_after", "boundary_seen", "truth_margin", "error"]
SINGLED_OUT = 10.0  # AIC: the truth's family ahead of every other family's refit by this much (claims.RIVAL_AIC)


def family_of(kind: str) -> str:
    return FAMILIES.get(kind, kind)


def left_out(kind: str) -> frozenset:
    """The kinds removed from the library for a --leave-out case of truth `kind` (its family)."""
    fam = family_of(kind)
    return frozenset([kind] + [k for k, f in FAMILIES.items() if f == fam])


def grade_of(s) -> str:
    """'named', 'explained' or 'tentative' of an accepted hypothesis (a library without grades: named
    unless tentative)."""
    g = getattr(s, "grade", None)
    if g:
        return g
    return "named" if s.determined else "tentative"


def _diagnose(problem, leave: frozenset):
    """diagnose with the kinds `leave` removed from the library."""
    import inspect

    from geoback.diagnosis import diagnose

    if not leave:
        return diagnose(problem)
    if "exclude" in inspect.signature(diagnose).parameters:
        from geoback.diagnosis.hypotheses import KINDS as LIBRARY

        return diagnose(problem, exclude=leave & set(LIBRARY))
    from geoback.diagnosis import hypotheses, yielding  # older code: the rows taken out for this call

    saved = hypotheses.CATALOGUE, yielding.screen
    hypotheses.CATALOGUE = tuple(k for k in saved[0] if k.key not in leave)
    if "yielding" in leave:
        yielding.screen = lambda *a, **k: []
    try:
        return diagnose(problem)
    finally:
        hypotheses.CATALOGUE, yielding.screen = saved


def cause_of(kind: str) -> str:
    if kind in NULL_KINDS:
        return "null"
    if kind in ("nothing", "error", ""):
        return kind or "nothing"
    return "instrument" if kind in INSTRUMENT_KINDS else "ground"


def _loguniform(rng, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


# ------------------------------------------------------------------------------------------ cases
def _tunnel(name, R, zc, width, depth, gamma, K0, E, nu, size_tunnel, size_far) -> dict:
    """A case's name, geometry, one-layer ground ('clay') and mesh."""
    return {"name": name,
            "geometry": {"radius": round(R, 3), "axis_depth": round(zc, 3), "width": width, "depth": depth},
            "ground": {"unit_weight": round(gamma, 3), "K0": round(K0, 4),
                       "layers": [{"name": "clay", "top": 0.0, "E": E, "nu": round(nu, 4)}]},
            "mesh": {"size_tunnel": size_tunnel, "size_far": size_far}}


def _stream(master_seed: int, index: int, tag: int | None, draw: int) -> np.random.Generator:
    """A case's random stream: [seed, index(, tag)], and for a redraw (draw > 0) a stream of its own,
    [seed, index, REDRAW, tag or 0, draw] (the first draws stay as they were)."""
    if draw:
        return np.random.default_rng([master_seed, index, REDRAW, tag or 0, draw])
    return np.random.default_rng([master_seed, index] + ([] if tag is None else [tag]))


REDRAW = 7  # the tag of a redraw's stream
MAX_DRAWS = 5  # a yielding truth whose fine-mesh run does not converge is drawn again, at most this often


def random_case(index: int, kind: str, master_seed: int, strong: bool = False, draw: int = 0) -> dict:
    """The case data (baseline model, no readings), the truth's extras and the noise seed.
    strong: effect magnitudes from the upper half (in log) of each kind's range (coverage study).
    draw: 0 the case's own draw; k > 0 its k-th redraw (a stream of its own)."""
    rng = _stream(master_seed, index, None, draw)

    def _effect(rng, lo, hi):  # an effect's magnitude: from the upper half (in log) when strong
        return _loguniform(rng, math.sqrt(lo * hi) if strong else lo, hi)
    R = float(rng.uniform(2.0, 4.0))
    zc = float(rng.uniform(2.5 * R, 5.0 * R))
    width = round(15.0 * R, 2)
    depth = round(zc + 25.0, 2)
    E = _loguniform(rng, 5000.0, 50000.0)
    nu = float(rng.uniform(0.2, 0.45))
    K0 = float(rng.uniform(0.5, 1.5))
    gamma = float(rng.uniform(18.0, 21.0))

    instruments = []
    n_incl = int(rng.integers(1, 3))
    xs = sorted(rng.uniform(R + 1.5, R + 6.0, n_incl))
    if n_incl == 2 and xs[1] - xs[0] < 1.0:
        xs[1] = xs[0] + 1.0
    layout = []
    for j, x in enumerate(xs):
        toe = float(min(rng.uniform(zc + R + 4.0, zc + R + 12.0), depth - 1.0))
        stations = int(rng.integers(12, 21))
        spacing = round(toe / (stations + 0.5), 3)
        instruments.append({"name": f"I{j + 1}", "kind": "inclinometer", "x": round(float(x), 3),
                            "toe_depth": round(toe, 3), "spacing": spacing, "stations": stations,
                            "sigma": round(float(rng.uniform(0.0002, 0.0005)), 6)})
        layout.append(f"I{j + 1}@x{x:.1f}/{stations}")
    length = zc - R - 0.5
    ext_spacing = 1.0 if length >= 4.0 else round(length / 4.0, 3)
    n_ext = max(int(math.floor(length / ext_spacing + 1e-9)), 1)
    instruments.append({"name": "X1", "kind": "extensometer", "start": [0.0, 0.0], "end": [0.0, -round(length, 3)],
                        "spacing": ext_spacing, "stations": n_ext,
                        "sigma": round(float(rng.uniform(0.0001, 0.0003)), 6), "var_a": 1.0e-8})
    layout.append(f"X1/{n_ext}")
    if rng.uniform() < 0.6:
        n_pts = int(rng.integers(5, 10))
        xmax = min(width - 1.0, 2.5 * zc)
        pts = [[round(float(v), 3), 0.0] for v in np.linspace(0.0, xmax, n_pts)]
        instruments.append({"name": "S", "kind": "points", "points": pts, "components": ["uy"],
                            "sigma": round(float(rng.uniform(0.0003, 0.001)), 6)})
        layout.append(f"S/{n_pts}")

    e_prior = None
    values: dict = {}
    extra_layer = None
    parameter, magnitude = "", float("nan")
    if kind == "stiffness-gradient":
        parameter, magnitude = "Egrad[clay]", _effect(rng, 0.2, 3.0) * E / 30.0
        values = {parameter: magnitude}
    elif kind == "layer-boundary":
        ratio = _effect(rng, 1.5, 4.0)
        z = float(rng.uniform(zc + R + 2.0, zc + 12.0))
        extra_layer = {"name": "sand", "top": round(z, 3), "E": ratio * E, "nu": nu}
        parameter, magnitude = f"E2/E (top {z:.2f} m)", ratio
    elif kind == "anisotropy":  # below the positive-definite limit (1 - nu) / (2 nu^2) of high nu
        parameter = "n[clay]"
        magnitude = min(_effect(rng, 1.1, 2.0), 0.9 * (1 - round(nu, 4)) / (2 * round(nu, 4) ** 2))
        values = {parameter: magnitude}
    elif kind == "K0-gradient":
        parameter, magnitude = "K0grad", float(rng.choice([-1.0, 1.0])) * _effect(rng, 0.01, 0.08)
        values = {parameter: magnitude}
    elif kind == "integration-constant":
        parameter, magnitude = "B[I1]", float(rng.choice([-1.0, 1.0])) * _effect(rng, 0.001, 0.008)
        values = {parameter: magnitude}
    elif kind == "stress-release":
        parameter, magnitude = "beta", 1.0 - _effect(rng, 0.05, 0.4)
        values = {parameter: magnitude}
        e_prior = {"mean": E, "std": 0.05 * E}
    elif kind == "bias-shift":
        parameter, magnitude = "bias[I1]", float(rng.choice([-1.0, 1.0])) * _effect(rng, 3e-5, 5e-4)
        values = {parameter: magnitude}
    elif kind == "depth-offset":
        i1 = instruments[0]
        top = i1["toe_depth"] - i1["stations"] * i1["spacing"]  # the shallowest station's depth
        d = _effect(rng, 0.1, 0.6)
        magnitude = d if rng.uniform() < 0.5 else -min(d, 0.8 * top)
        parameter = "zoff[I1]"
        values = {parameter: magnitude}
    elif kind != "null":
        raise ValueError(kind)

    e_param = {"name": "E", "initial": E * _loguniform(rng, 0.4, 2.5), "bounds": [100.0, 1.0e6]}
    if e_prior:
        e_param["prior"] = e_prior
    data = {
        **_tunnel(f"bench-{index:03d}-{kind}", R, zc, width, depth, gamma, K0, E, nu, round(R / 7.5, 4), 5.0),
        "instruments": instruments,
        "parameters": [e_param, {"name": "K0", "initial": float(rng.uniform(0.4, 1.6)), "bounds": [0.05, 5.0]}],
    }
    noise_seed = int(rng.integers(0, 2**31 - 1))
    if e_prior:  # the laboratory's E is itself uncertain: its mean drawn from N(true E, its std)
        e_prior["mean"] = float(E + e_prior["std"] * rng.standard_normal())
    truth = dict(values)  # the extra parameters' true values, by the names diagnose gives them
    if extra_layer:
        truth = {"E[clay_below]": extra_layer["E"], "depth[clay]": extra_layer["top"]}
    return {"index": index, "kind": kind, "data": data, "values": values, "extra_layer": extra_layer,
            "parameter": parameter, "magnitude": magnitude, "noise_seed": noise_seed, "truth": truth,
            "R": R, "zc": zc, "E": E, "nu": nu, "K0": K0, "layout": " ".join(layout)}


def random_staged_case(index: int, kind: str, master_seed: int) -> dict:
    """A random two-stage lined tunnel (cases/staged-tunnel.yaml's layout: release beta before a
    lining, the rest on ground and lining together; bedrock below) read after each stage by an
    inclinometer beside it, an extensometer above the crown and surface points. The case identifies
    E and K0 with the release before the lining and the lining's E as assumed; the truth differs in
    one of them (or in nothing: 'null-staged').

      release-before-lining  beta[advance] = assumed beta +- d, d log-uniform in (0.05, 0.3), kept
                             in (0.05, 0.95); assumed beta uniform in (0.2, 0.7)
      lining-stiffness       E[shotcrete] = assumed E_l x f or / f, f log-uniform in (2, 6); assumed
                             E_l log-uniform in (2, 15) GPa
      null-staged            nothing (noise only)"""
    rng = np.random.default_rng([master_seed, index, 1])  # a stream of its own (not random_case's)
    R = float(rng.uniform(2.5, 4.0))
    zc = float(rng.uniform(3.0 * R, 5.0 * R))
    depth = round(zc + R + float(rng.uniform(6.0, 12.0)), 2)  # bedrock 6-12 m below the invert
    width = round(15.0 * R, 2)
    E = _loguniform(rng, 10000.0, 60000.0)
    nu = float(rng.uniform(0.3, 0.49))
    K0 = float(rng.uniform(0.5, 1.2))
    gamma = float(rng.uniform(18.0, 21.0))
    t = float(rng.uniform(0.2, 0.35))
    El = _loguniform(rng, 2.0e6, 15.0e6)  # young or cracked shotcrete
    beta0 = float(rng.uniform(0.2, 0.7))

    x = float(rng.uniform(R + 1.5, R + 5.0))
    toe = depth - 1.0
    stations = int(rng.integers(8, 15))
    spacing = round((toe - 1.5) / stations, 3)
    length = zc - R - 1.0
    n_ext = max(int(length // 2.0), 2)
    ext_spacing = round(length / (n_ext + 0.5), 3)
    n_pts = int(rng.integers(5, 9))
    pts = [[round(float(v), 3), 0.0] for v in np.linspace(0.0, min(width - 1.0, 2.0 * zc), n_pts)]
    instruments = [
        {"name": "I1", "kind": "inclinometer", "x": round(x, 3), "toe_depth": round(toe, 3), "reference": "toe",
         "spacing": spacing, "stations": stations, "sigma": round(float(rng.uniform(0.0001, 0.0003)), 6)},
        {"name": "X1", "kind": "extensometer", "start": [0.0, 0.0], "end": [0.0, -round(length, 3)],
         "spacing": ext_spacing, "stations": n_ext, "sigma": round(float(rng.uniform(0.0001, 0.0003)), 6),
         "var_a": 4.0e-8},
        {"name": "S1", "kind": "points", "points": pts, "components": ["uy"],
         "sigma": round(float(rng.uniform(0.0003, 0.0008)), 6)},
    ]
    layout = f"I1@x{x:.1f}/{stations} X1/{n_ext} S1/{n_pts} (2 stages)"

    values: dict = {}
    parameter, magnitude = "", float("nan")
    if kind == "release-before-lining":
        d = _loguniform(rng, 0.05, 0.3)
        up = rng.uniform() < 0.5
        b = beta0 + d if up else beta0 - d
        if not 0.05 <= b <= 0.95:
            b = beta0 - d if up else beta0 + d
        parameter, magnitude = "beta[advance]", float(min(max(b, 0.05), 0.95))
        values = {parameter: magnitude}
    elif kind == "lining-stiffness":
        f = _loguniform(rng, 2.0, 6.0)
        parameter = "E[shotcrete]"
        magnitude = El * f if rng.uniform() < 0.5 else El / f
        values = {parameter: magnitude}
    elif kind != "null-staged":
        raise ValueError(kind)
    data = {
        **_tunnel(f"bench-{index:03d}-{kind}", R, zc, width, depth, gamma, K0, E, nu, round(R / 8.0, 4), 4.0),
        "construction": {
            "lining": {"name": "shotcrete", "thickness": round(t, 3), "E": El, "nu": 0.2},
            "stages": [{"name": "advance", "release": round(beta0, 4)},
                       {"name": "lined", "install": "shotcrete", "release": 1.0}]},
        "instruments": instruments,
        "parameters": [{"name": "E", "initial": E * _loguniform(rng, 0.4, 2.5), "bounds": [1000.0, 1.0e6]},
                       {"name": "K0", "initial": float(rng.uniform(0.4, 1.4)), "bounds": [0.1, 3.0]}],
    }
    noise_seed = int(rng.integers(0, 2**31 - 1))
    return {"index": index, "kind": kind, "data": data, "values": values, "extra_layer": None, "strength": None,
            "staged": True, "parameter": parameter, "magnitude": magnitude, "noise_seed": noise_seed,
            "truth": dict(values), "R": R, "zc": zc, "E": E, "nu": nu, "K0": K0, "layout": layout}


def plastic_cohesion(p0: float, phi: float, ratio: float) -> float:
    """c' for which an unsupported circular tunnel under the hydrostatic stress p0 has a Mohr-Coulomb
    plastic zone to ratio x R (Salencon's closed form, wall pressure 0):
    R_p / R = [2 (p0 (Kp - 1) + sc) / ((1 + Kp) sc)]^(1 / (Kp - 1)), sc = 2 c cos phi / (1 - sin phi)."""
    sp = math.sin(math.radians(phi))
    kp = (1 + sp) / (1 - sp)
    sc = 2 * p0 * (kp - 1) / (ratio ** (kp - 1) * (1 + kp) - 2)
    return sc * (1 - sp) / (2 * math.cos(math.radians(phi)))


def unconfined(c: float, phi: float) -> float:
    """The unconfined strength [kPa] of c [kPa], phi [deg] (closed_form.unconfined_strength)."""
    from geoback.physics.plasticity.closed_form import unconfined_strength

    return float(unconfined_strength(c, math.radians(phi)))


def random_yielding_case(index: int, master_seed: int, draw: int = 0) -> dict:
    """A random tunnel as random_case draws it (K0 redrawn in (0.8, 1.2), a coarser mesh: the truth
    is non-linear), its ground in truth Mohr-Coulomb: phi' uniform in (22, 35) degrees, psi' in (0, 5),
    c' from the closed form for a plastic zone to R_p / R uniform in (1.2, 1.7) under the mean
    in-situ stress at the axis (an estimate: K0 != 1, the surface, the mesh). The case is elastic.
    draw: 0 the case's own draw; k > 0 its k-th redraw (run_one redraws a truth whose fine-mesh run
    does not converge: the case is then another tunnel, drawn from the seed)."""
    spec = random_case(index, "null", master_seed, draw=draw)
    rng = _stream(master_seed, index, 2, draw)
    K0 = float(rng.uniform(0.8, 1.2))
    phi, psi, ratio = float(rng.uniform(22.0, 35.0)), float(rng.uniform(0.0, 5.0)), float(rng.uniform(1.2, 1.7))
    data = spec["data"]
    data["name"] = f"bench-{index:03d}-yielding"
    data["ground"]["K0"] = round(K0, 4)
    data["mesh"] = {"size_tunnel": round(spec["R"] / 6.0, 4), "size_far": 6.0}
    p0 = data["ground"]["unit_weight"] * spec["zc"] * (1 + K0) / 2
    c = plastic_cohesion(p0, phi, ratio)
    spec.update(kind="yielding", K0=K0, parameter=f"c' (phi {phi:.0f}, Rp/R {ratio:.2f})", magnitude=c,
                strength={"model": "mohr-coulomb", "c": round(c, 3), "phi": round(phi, 3), "psi": round(psi, 3)},
                truth={"c[clay]": round(c, 3), "ucs[clay]": unconfined(round(c, 3), round(phi, 3))},
                seed=master_seed, draw=draw)
    return spec


def coverage(d, truth: dict) -> list[dict]:
    """Whether each extra parameter's 95 % interval (final joint fit, as reported) holds the truth,
    for the FIRST accepted hypothesis; a boundary's depth by its profile likelihood."""
    if not d.accepted:
        return []
    s = d.accepted[0]
    out = []
    selective = d.selective(s) if hasattr(d, "selective") else {}  # (older code: none)
    for name, v, sd, lo, hi in d.estimates(s):
        if name in truth:
            sel = selective.get(name)  # allowing for the cause's selection (one-parameter causes), else the usual
            a, b = (sel.low, sel.high) if sel is not None else (lo, hi)
            out.append({"name": name, "truth": truth[name], "estimate": v, "std": sd, "low": lo, "high": hi,
                        "covered": bool(lo <= truth[name] <= hi), "tentative": not s.determined,
                        "low_adjusted": a, "high_adjusted": b, "adjusted": sel is not None,
                        "covered_adjusted": bool(a <= truth[name] <= b)})
    strength = getattr(d, "strength", {}).get(s.hypothesis.key)  # yielding: phi' and psi profiled out
    if strength is not None and f"ucs[{strength.layer}]" in truth:
        t = truth[f"ucs[{strength.layer}]"]
        out.append({"name": f"ucs[{strength.layer}]", "truth": t, "estimate": float("nan"), "std": float("nan"),
                    "low": strength.ucs_low, "high": strength.ucs_high,
                    "covered": bool(strength.ucs_low <= t <= strength.ucs_high), "tentative": not s.determined})
    prof = d.depth_profile(s)
    if prof is not None and f"depth[{prof.layer}]" in truth:
        t = truth[f"depth[{prof.layer}]"]
        half = max(prof.high - prof.z_hat, prof.z_hat - prof.low) / 1.96
        out.append({"name": f"depth[{prof.layer}]", "truth": t, "estimate": prof.z_hat, "std": half,
                    "low": prof.low, "high": prof.high, "covered": bool(prof.low <= t <= prof.high),
                    "tentative": not s.determined})
    return out


def _stack(readings: dict, analysis) -> np.ndarray:
    return np.concatenate([readings[b.name] for b in analysis.simulation.survey.blocks])


def _stack_stages(readings: dict, analysis) -> np.ndarray:
    """{instrument: {stage: readings}} stacked in the survey's (instrument, stage) block order."""
    return np.concatenate([readings[b.name][b.stage] for b in analysis.simulation.survey.blocks])


def _staged_noise(clean: np.ndarray, analysis, seed: int) -> np.ndarray:
    """Noise drawn from each (instrument, stage) block's C_x, independent from stage to stage."""
    rng = np.random.default_rng(seed)
    out, offset = clean.copy(), 0
    for b in analysis.simulation.survey.blocks:
        out[offset:offset + b.m] += np.linalg.cholesky(b.covariance) @ rng.standard_normal(b.m)
        offset += b.m
    return out


def _with_noise(clean: dict, loaded, seed: int) -> dict:
    """Noise drawn from each instrument's C_x, as synthetic_readings(noise_seed=seed) draws it."""
    from geoback.observation.instruments import case_blocks

    rng = np.random.default_rng(seed)
    return {b.name: clean[b.name] + np.linalg.cholesky(b.covariance) @ rng.standard_normal(b.m)
            for b in case_blocks(loaded)}


def _row_of(spec: dict) -> dict:
    row = {k: "" for k in COLUMNS}
    row.update(case=spec["data"]["name"], kind=spec["kind"], parameter=spec["parameter"], cause=cause_of(spec["kind"]),
               magnitude=spec["magnitude"], noise_seed=spec["noise_seed"], R=round(spec["R"], 3),
               axis_depth=round(spec["zc"], 3), E=round(spec["E"], 1), nu=round(spec["nu"], 3),
               K0=round(spec["K0"], 3), layout=spec["layout"], draw=spec.get("draw", 0))
    return row


def truth_readings(spec: dict, folder: str) -> tuple:
    """(spec, loaded, problem with the noisy readings, x_truth, x_base) of a case: the truth on a mesh twice
    as fine. A yielding truth whose fine-mesh run does not converge (ForwardFailure) is drawn again from the
    seed (random_yielding_case(draw=k), k = 1, 2, ... up to MAX_DRAWS draws): the benchmark measures the
    diagnosis, not whether the truth it made up can be solved."""
    from geoback.case.loading import LoadedCase, case_from_data
    from geoback.errors import ForwardFailure
    from geoback.inference.identification import prepare
    from geoback.inference.synthetic import synthetic_readings

    while True:
        path = Path(folder) / f"{spec['data']['name']}.yaml"
        loaded = LoadedCase(case_from_data(copy.deepcopy(spec["data"])), path, {})
        truth_data = copy.deepcopy(spec["data"])
        if spec["extra_layer"]:
            truth_data["ground"]["layers"].append(dict(spec["extra_layer"]))
        if spec.get("strength"):  # the truth's ground yields (the case's stays elastic)
            truth_data["ground"]["layers"][0].update(spec["strength"])
        truth = LoadedCase(case_from_data(truth_data), path, {})
        problem = prepare(loaded, with_readings=False)
        try:
            if spec.get("staged"):  # every instrument read after every stage; noise drawn per (instrument, stage)
                clean = synthetic_readings(truth, refine=2.0, values=spec["values"], noise_seed=None, by_stage=True)
            else:
                clean = synthetic_readings(truth, refine=2.0, values=spec["values"], noise_seed=None)
        except ForwardFailure:
            draw = spec.get("draw", 0) + 1
            if not spec.get("strength") or draw >= MAX_DRAWS:
                raise
            spec = {**random_yielding_case(spec["index"], spec["seed"], draw),
                    **{k: spec[k] for k in ("leave_out",) if k in spec}}
            continue
        break
    if spec.get("staged"):
        base_clean = synthetic_readings(loaded, refine=2.0, values=None, noise_seed=None, by_stage=True)
        x_truth, x_base = _stack_stages(clean, problem), _stack_stages(base_clean, problem)
        problem = problem.with_readings(_staged_noise(x_truth, problem, spec["noise_seed"]))
    else:
        noisy = _with_noise(clean, loaded, spec["noise_seed"])  # what synthetic_readings(noise_seed=...) gives
        base_clean = synthetic_readings(loaded, refine=2.0, values=None, noise_seed=None)
        x_truth, x_base = _stack(clean, problem), _stack(base_clean, problem)
        problem = problem.with_readings(_stack(noisy, problem))
    return spec, loaded, problem, x_truth, x_base


def run_one(spec: dict, folder: str, show: bool = False) -> dict:
    """Truth readings, effect size, raw movement, and the diagnosis of one case."""
    from geoback.inference.estimate import fit

    row = _row_of(spec)
    try:
        drawn, _, problem, x_truth, x_base = truth_readings(spec, folder)
        if drawn is not spec:  # redrawn: the row describes the case diagnosed
            spec = drawn
            row.update({k: v for k, v in _row_of(spec).items() if v != ""})
        sigma = np.sqrt(np.diag(problem.misfit.data.covariance))
        row["raw_movement"] = float(np.max(np.abs(x_truth - x_base) / sigma))
        row["readings"] = len(x_truth)

        t0 = time.perf_counter()
        leave = frozenset(spec.get("leave_out") or ())
        row["left_out"] = " ".join(sorted(leave))
        d = _diagnose(problem, leave)
        row["seconds"] = time.perf_counter() - t0
        if show:
            from geoback.reports.diagnosis_report import diagnosis_text

            print(diagnosis_text(d))

        truth_fit = fit(problem.misfit.with_measured(x_truth), problem.settings)  # what the baseline cannot absorb
        row["effect_size"] = float(math.sqrt(max(truth_fit.J, 0.0)))

        kinds = [s.hypothesis.kind for s in d.accepted]
        named = kinds[0] if kinds else "nothing"
        row["named"] = named
        row["cause"], row["named_cause"] = cause_of(spec["kind"]), cause_of(named)
        row["accepted"] = " + ".join(s.hypothesis.key for s in d.accepted)
        row["correct"] = (named == "nothing") if spec["kind"] in NULL_KINDS else (named == spec["kind"])
        row["grade"] = grade_of(d.accepted[0]) if d.accepted else "nothing"
        row["failed_checks"] = " ".join(f"{c.name}" + (f"({' '.join(c.detail.get('rivals', []))})" if c.name == "rivals"
                                                       else "") for s in d.accepted
                                        for c in getattr(s, "checks", {}).values() if not c.passed)
        row["adequate_after"] = bool(d.adequate_after)
        row["p_after"] = float(d.final_reliability.p_value)  # the final joint fit's chi^2 test (claims.adequacy)
        row["boundary_seen"] = " ".join(  # check 8 of a stratum accepted: readings below, their gain / the refit's
            f"{c.detail['readings_below']}:{c.detail['below_gain']:.3g}/{c.detail['gain']:.3g}"
            f":d{c.detail['change_below']:.3g}:z{c.detail['z']:.3g}"
            f"@{c.detail['depth']:.3g}/{c.detail['deepest_reading']:.3g}"
            for s in d.accepted if (c := getattr(s, "checks", {}).get("boundary-seen")) is not None
            and "depth" in c.detail)
        if d.accepted:
            s = d.accepted[0]
            row["tentative"] = not s.determined
            row["estimate"] = " ".join(f"{n}={v:.4g}±{sd:.2g}[{lo:.4g},{hi:.4g}]" for n, v, sd, lo, hi in d.estimates(s))
            prof = d.depth_profile(s)
            if prof is not None:
                row["estimate"] += f" z={prof.z_hat:.4g}[{prof.low:.4g},{prof.high:.4g}]"
        rivals = [r.rival.hypothesis.key for r in d.rounds if r.rival is not None]
        row["rival"] = " ".join(rivals)
        if row["correct"] and spec["kind"] not in NULL_KINDS:
            cov = coverage(d, spec["truth"])
            row["coverage"] = cov
            row["covered"] = " ".join(f"{c['name']}:{'yes' if c['covered'] else 'NO'}" for c in cov)
        r0 = d.rounds[0]
        row["p_before"] = r0.p_value
        scored = [s for s in r0.ranking if s.collinear_with is None]
        row["top_score_kind"] = scored[0].hypothesis.kind if scored else ""
        row["round1"] = " ".join(  # the refitted hypotheses of round 1: key, dJ, AIC, converged?
            f"{s.hypothesis.key}:dJ={s.dJ:.4g}:AIC={s.aic:.6g}{'' if s.refit.status == 'converged' else ':NC'}"
            for s in r0.ranking if s.refit is not None)
        row["truth_margin"] = truth_margin(r0, spec["kind"])
        row["chi2dof_before"] = d.baseline_reliability.reduced_chi2
        row["chi2dof_after"] = d.final_reliability.reduced_chi2
    except Exception as exc:  # one broken case is reported, not fatal
        row["error"] = f"{type(exc).__name__}: {exc}".replace("\n", " ")[:300]
        row["named"] = row["named"] or "error"
        row["named_cause"] = row["named_cause"] or "error"
        row["correct"] = False
    return row


def truth_margin(r0, kind: str) -> float:
    """How far round 1's best refit of the truth's family is ahead of the best refit of every other family,
    in AIC (positive: ahead; nan: one of them not refitted). Where it is below SINGLED_OUT the readings do
    not single the truth out from another family (raw AIC of the settled refits: the rival check's quasi-AIC
    and its rivals' own checks left aside)."""
    fam = family_of(kind)
    aic = {}
    for s in r0.ranking:
        if s.refit is not None and getattr(s, "settled", True) and math.isfinite(s.aic):
            f = family_of(s.hypothesis.kind) == fam
            aic[f] = min(aic.get(f, math.inf), s.aic)
    if True not in aic or False not in aic:
        return float("nan")
    return float(aic[False] - aic[True])


# ------------------------------------------------------------------------------------------ output
def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}" if math.isfinite(v) else "nan"
    return str(v)


def confusion(rows: list[dict], title: str) -> str:
    truths = [k for k in ALL_KINDS + list(NULL_KINDS) if any(r["kind"] == k for r in rows)]
    extra = [k for k in STAGED_KINDS + YIELDING_KINDS if any(k in (r["kind"], r["named"]) for r in rows)]
    named = KINDS + extra + ["nothing"] + sorted({r["named"] for r in rows} - set(KINDS + extra) - {"nothing"})
    short = {"stiffness-gradient": "Egrad", "layer-boundary": "layer", "anisotropy": "aniso",
             "K0-gradient": "K0grad", "integration-constant": "int-const", "stress-release": "beta",
             "bias-shift": "bias", "depth-offset": "zoff", "nothing": "nothing", "error": "error",
             "release-before-lining": "rel-lining", "lining-stiffness": "lining-E", "yielding": "yielding"}
    cols = [c for c in named if c in KINDS + extra + ["nothing"] or any(r["named"] == c for r in rows)]
    w0 = max(len(t) for t in truths + ["truth \\ named"]) + 1
    width = {c: 11 if c in extra else 10 for c in cols}  # the staged kinds' short names are 10 wide
    head = "truth \\ named".ljust(w0) + "".join(short.get(c, c).rjust(width[c]) for c in cols) + "   n  correct"
    lines = [title, head, "-" * len(head)]
    for t in truths:
        sub = [r for r in rows if r["kind"] == t]
        counts = [sum(r["named"] == c for r in sub) for c in cols]
        ok = sum(bool(r["correct"]) for r in sub)
        cells = "".join(str(n).rjust(width[c]) for n, c in zip(counts, cols))
        lines.append(t.ljust(w0) + cells + f"{len(sub):4d}  {ok:3d}"
                     f" ({100 * ok / len(sub):.0f} %)")
    if not truths:
        lines.append("(no cases)")
    return "\n".join(lines)


def cause_confusion(rows: list[dict], title: str) -> str:
    """Truth cause (instrument error / ground physics / null) against the named cause."""
    truths = [t for t in ("instrument", "ground", "null") if any(r["cause"] == t for r in rows)]
    cols = ["instrument", "ground", "nothing"] + sorted({r["named_cause"] for r in rows}
                                                         - {"instrument", "ground", "nothing", ""})
    head = "truth \\ named".ljust(16) + "".join(c.rjust(12) for c in cols) + "   n"
    lines = [title, head, "-" * len(head)]
    for t in truths:
        sub = [r for r in rows if r["cause"] == t]
        lines.append(t.ljust(16) + "".join(str(sum(r["named_cause"] == c for r in sub)).rjust(12) for c in cols)
                     + f"{len(sub):4d}")
    return "\n".join(lines)


def coverage_table(rows: list[dict]) -> tuple[str, list[dict]]:
    """Coverage of the extra parameters' 95 % intervals over the correctly named cases, per kind."""
    table = []
    for kind in ALL_KINDS + ["all"]:
        items = [c for r in rows if r.get("coverage") and (kind == "all" or r["kind"] == kind) for c in r["coverage"]]
        if not items:
            continue
        n, k = len(items), sum(c["covered"] for c in items)
        ka = sum(c.get("covered_adjusted", c["covered"]) for c in items)
        p, pa = k / n, ka / n
        table.append({"kind": kind, "intervals": n, "covered": k, "coverage": p,
                      "se": math.sqrt(max(p * (1 - p), 1e-12) / n), "covered_adjusted": ka, "coverage_adjusted": pa,
                      "se_adjusted": math.sqrt(max(pa * (1 - pa), 1e-12) / n)})
    lines = ["Coverage of the extra parameters' 95 % intervals (final joint fit), correctly named cases; 'allowing",
             "for selection': one-parameter causes' intervals adjusted for their acceptance (diagnosis/selection.py):",
             "kind                  intervals covered  coverage      allowing for selection"]
    lines += [f"{t['kind']:<22}{t['intervals']:>9}{t['covered']:>8}  {100 * t['coverage']:5.1f} % ± {100 * t['se']:.1f}"
              f"    {100 * t['coverage_adjusted']:5.1f} % ± {100 * t['se_adjusted']:.1f}"
              for t in table]
    return "\n".join(lines), table


def fit_table(rows: list[dict]) -> str:
    """Per truth kind: effect size (median, range) and chi^2/dof of the baseline before and of the
    final model after diagnose (medians), and the median seconds per diagnose."""
    def med(sub, key):
        v = [r[key] for r in sub if isinstance(r[key], float) and math.isfinite(r[key])]
        return (float(np.median(v)), min(v), max(v)) if v else (float("nan"),) * 3

    lines = ["Per kind: effect size median [min, max]; chi2/dof before -> after (medians); seconds per diagnose:",
             "kind                      n  effect size                  chi2/dof before -> after   s (median)"]
    for kind in ALL_KINDS + list(NULL_KINDS):
        sub = [r for r in rows if r["kind"] == kind]
        if not sub:
            continue
        e, b, a, t = med(sub, "effect_size"), med(sub, "chi2dof_before"), med(sub, "chi2dof_after"), med(sub, "seconds")
        lines.append(f"{kind:<22}{len(sub):>5}  {e[0]:7.2f} [{e[1]:6.2f}, {e[2]:7.2f}]     "
                     f"{b[0]:8.2f} -> {a[0]:6.2f}           {t[0]:6.1f}")
    return "\n".join(lines)


def summary(rows: list[dict], seconds: float) -> tuple[str, bool]:
    concealed = [r for r in rows if r["kind"] not in NULL_KINDS]
    nulls = [r for r in rows if r["kind"] in NULL_KINDS]
    big = [r for r in concealed if isinstance(r["effect_size"], float) and r["effect_size"] > THRESHOLD]
    raw = [r for r in concealed if isinstance(r["raw_movement"], float) and r["raw_movement"] > THRESHOLD]
    out = [
        "Definitions: effect size = sqrt(J_min) of the BASELINE model fitted to the truth's noise-free "
        "readings",
        "(the part of the effect the baseline parameters cannot absorb, in sigma units); raw movement = "
        "max_i |x_truth - x_base| / sigma_i",
        "(noise-free, true baseline values). Answer = kind of the first accepted hypothesis; null case: "
        "false alarm if anything is accepted.",
        "",
        confusion(rows, f"Confusion matrix, all cases ({len(rows)}):"),
        "",
        confusion(big + nulls, f"Confusion matrix, concealed cases with effect size > {THRESHOLD:g} "
                               f"({len(big)}) and null cases ({len(nulls)}) - the floor applies here:"),
        "",
        confusion(raw + nulls, f"Confusion matrix, concealed cases with raw movement > {THRESHOLD:g} sigma "
                               f"({len(raw)}) and null cases ({len(nulls)}):"),
        "",
        cause_confusion(big + nulls, f"By cause, concealed cases with effect size > {THRESHOLD:g} and null cases:"),
        "",
        coverage_table(rows)[0],
        "",
        fit_table(rows),
        "",
    ]
    ok = True
    bias = [r for r in big if r["kind"] == "bias-shift"]
    if bias:
        named = sum(r["named_cause"] == "instrument" for r in bias)
        passed = named == len(bias)
        ok &= passed
        out.append(f"bias-shift cases named as instrument error (effect size > {THRESHOLD:g}): {named}/{len(bias)} "
                   f"({'PASS' if passed else 'FAIL'}: all must be)")
    tentative = [r for r in concealed if r["tentative"] is True]
    rivals = [r for r in concealed if r["rival"]]
    out.append(f"tentative answers (a parameter not determined): {len(tentative)}; answers with a rival within "
               f"2 AIC: {len(rivals)}")

    def rate(sub):
        n = len(sub)
        k = sum(bool(r["correct"]) for r in sub)
        return (k / n if n else float("nan")), k, n

    acc, k, n = rate(big)
    if n:
        passed = acc >= FLOOR_ACCURACY
        ok &= passed
        out.append(f"correct names, effect size > {THRESHOLD:g}:    {k}/{n} = {100 * acc:.1f} % "
                   f"(floor >= {100 * FLOOR_ACCURACY:.0f} %: {'PASS' if passed else 'FAIL'})")
    else:
        ok = False
        out.append(f"correct names, effect size > {THRESHOLD:g}: no such case")
    if n:  # issue 24's grades: a right kind that is only 'explained but not singled out' is not named
        named_right = sum(bool(r["correct"]) and r["grade"] == "named" for r in big)
        wrong_named = sum(not r["correct"] and r["grade"] == "named" for r in big)
        out.append(f"  of which named (grade 'named', claim checks passed): {named_right}/{n} = "
                   f"{100 * named_right / n:.1f} %; a wrong kind named: {wrong_named}/{n}")
        for kind in ALL_KINDS:
            sub = [r for r in big if r["kind"] == kind]
            if sub:
                out.append(f"    {kind:<22} right {sum(bool(r['correct']) for r in sub)}/{len(sub)}, named right "
                           f"{sum(bool(r['correct']) and r['grade'] == 'named' for r in sub)}/{len(sub)}")
        margin = [r for r in big if isinstance(r["truth_margin"], float) and math.isfinite(r["truth_margin"])]
        apart = [r for r in margin if r["truth_margin"] >= SINGLED_OUT]
        tied = [r for r in margin if r["truth_margin"] < SINGLED_OUT]

        def grades(sub):
            return (f"named right {sum(bool(r['correct']) and r['grade'] == 'named' for r in sub)}, explained right "
                    f"{sum(bool(r['correct']) and r['grade'] != 'named' for r in sub)}, a wrong kind named "
                    f"{sum(not r['correct'] and r['grade'] == 'named' for r in sub)}, of {len(sub)}")

        out.append(f"  what the readings allow (round 1's refits): the truth's family ahead of every other by >= "
                   f"{SINGLED_OUT:g} AIC in {len(apart)}/{len(margin)} cases ({n - len(margin)} more without "
                   f"refits of both): {grades(apart)};")
        out.append(f"    another family within {SINGLED_OUT:g} AIC of it (or ahead) in {len(tied)}: {grades(tied)} "
                   f"(naming one of a tie would be a guess)")
    acc_r, k_r, n_r = rate(raw)
    out.append(f"correct names, raw movement > {THRESHOLD:g} sigma: {k_r}/{n_r} = {100 * acc_r:.1f} %")
    for lo, hi in ((0, 3), (3, 5), (5, 10), (10, 30), (30, math.inf)):
        sub = [r for r in concealed if isinstance(r["effect_size"], float) and lo < r["effect_size"] <= hi]
        if sub:
            a, kk, nn = rate(sub)
            out.append(f"  effect size in ({lo:g}, {hi:g}]: {kk}/{nn} correct ({100 * a:.0f} %)")
    if any(r["kind"] == "null-staged" for r in nulls):  # false alarms on each model family apart
        for kind in NULL_KINDS:
            sub = [r for r in nulls if r["kind"] == kind]
            if sub:
                fa = sum(r["named"] != "nothing" for r in sub)
                named = ", ".join(sorted({r["named"] for r in sub} - {"nothing"}))
                out.append(f"  false alarms on {kind} cases: {fa}/{len(sub)}" + (f" (named: {named})" if named else ""))
    if nulls:
        fa = sum(r["named"] != "nothing" for r in nulls)
        p = fa / len(nulls)
        se = math.sqrt(p * (1 - p) / len(nulls))
        passed = p <= FLOOR_FALSE_ALARMS
        ok &= passed
        extra = f", 95 % upper bound {min(100.0, 300 / len(nulls)):.1f} % (rule of three)" if fa == 0 else ""
        out.append(f"false alarms on null cases:        {fa}/{len(nulls)} = {100 * p:.1f} % ± {100 * se:.1f} % "
                   f"(binomial s.e.{extra}; floor <= {100 * FLOOR_FALSE_ALARMS:.0f} %: "
                   f"{'PASS' if passed else 'FAIL'})")
        named_fa = sum(r["grade"] == "named" for r in nulls)
        out.append(f"  of which a cause named (grade 'named'): {named_fa}/{len(nulls)}; inadequate after: "
                   f"{sum(r['adequate_after'] is False for r in nulls)}/{len(nulls)}")
    errors = [r for r in rows if r["error"]]
    if errors:
        ok = False
        out.append(f"cases that raised: {len(errors)} (see the 'error' column)")
    null_eff = [r["effect_size"] for r in nulls if isinstance(r["effect_size"], float)]
    if null_eff:
        out.append(f"baseline mesh vs the 2x finer truth mesh (effect size of the null cases): median "
                   f"{np.median(null_eff):.2f}, max {max(null_eff):.2f}")
    secs = [r["seconds"] for r in rows if isinstance(r["seconds"], float)]
    searched = [r["seconds"] for r in rows if isinstance(r["seconds"], float) and r["round1"]]
    nan = float("nan")
    out.append(f"total time {seconds:.0f} s; median {np.median(secs) if secs else nan:.2f} s per diagnose "
               f"(max {max(secs) if secs else nan:.1f} s; median {np.median(searched) if searched else nan:.2f} s "
               f"over the {len(searched)} diagnoses that refitted hypotheses)")
    return "\n".join(out), ok


def leave_out_summary(rows: list[dict], seconds: float) -> tuple[str, bool]:
    """Confident wrong causes when the truth's family is not in the library (--leave-out)."""
    big = [r for r in rows if isinstance(r["effect_size"], float) and r["effect_size"] > THRESHOLD]
    lines = [f"Leave-one-family-out: {len(rows)} concealed cases, {len(big)} with effect size > {THRESHOLD:g}; "
             f"each diagnosed with its truth's family removed from the library.",
             "kind                    n>3  named  explained  tentative  nothing  error   what was named"]
    for kind in ALL_KINDS:
        sub = [r for r in big if r["kind"] == kind]
        if not sub:
            continue
        c = {g: sum(r["grade"] == g for r in sub) for g in ("named", "explained", "tentative", "nothing")}
        err = sum(bool(r["error"]) for r in sub)
        what = ", ".join(sorted({f"{r['named']}({r['grade']})" for r in sub if r["named"] not in ("nothing", "error")}))
        lines.append(f"{kind:<22}{len(sub):>5}{c['named']:>7}{c['explained']:>11}{c['tentative']:>11}"
                     f"{c['nothing']:>9}{err:>7}   {what}")
    k, n = confident_wrong(rows)
    ok = n > 0 and k / n <= FLOOR_CONFIDENT_WRONG and not any(r["error"] for r in rows)
    lines.append(f"confident wrong causes (named, family not the truth's), effect size > {THRESHOLD:g}: "
                 f"{rate_text(k, n)} (floor <= {100 * FLOOR_CONFIDENT_WRONG:.0f} %: {'PASS' if ok else 'FAIL'})")
    drawn = [r for r in rows if r.get("draw")]
    if drawn:
        lines.append("redrawn (the truth's fine-mesh run did not converge): "
                     + ", ".join(f"{r['case']} (draw {r['draw']})" for r in drawn))
    errors = [r for r in rows if r["error"]]
    if errors:
        lines.append(f"cases that raised: {len(errors)} ({', '.join(r['case'] for r in errors)}; see the 'error' column)")
    secs = [r["seconds"] for r in rows if isinstance(r["seconds"], float)]
    lines.append(f"total time {seconds:.0f} s; median {np.median(secs) if secs else float('nan'):.1f} s per diagnose, "
                 f"sum {sum(secs):.0f} s")
    return "\n".join(lines), ok


def write_csv(rows: list[dict], path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for r in sorted(rows, key=lambda r: (str(r.get("seed", "")), r["case"])):
            w.writerow([_fmt(r[c]) for c in COLUMNS])


def _init_worker() -> None:
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = "1"


def make_specs(args, seed: int) -> list[dict]:
    """The cases of one master seed, as the options ask."""
    rng = np.random.default_rng(seed)
    kinds = [KINDS[i % len(KINDS)] for i in range(args.concealed)]  # balanced, then shuffled
    kinds = [kinds[i] for i in rng.permutation(len(kinds))] + ["null"] * args.null
    if args.leave_out:
        kinds = [k for k in kinds if k != "null"]
    specs = [random_case(i, k, seed, strong=args.leave_out) for i, k in enumerate(kinds)]
    # opt-in kinds after those, drawn from streams of their own (the cases above are unchanged)
    staged = STAGED_KINDS + ["null-staged"]
    staged = [staged[i % len(staged)] for i in range(args.staged)]
    specs += [random_staged_case(len(specs) + i, k, seed) for i, k in enumerate(staged)]
    specs += [random_yielding_case(len(specs) + i, seed) for i in range(args.yielding)]
    if args.leave_out:
        specs = [{**sp, "leave_out": sorted(left_out(sp["kind"]))} for sp in specs if sp["kind"] not in NULL_KINDS]
    if getattr(args, "logged", False):  # boreholes logged the strata to the tunnel's invert (concealed strata lie deeper)
        for sp in specs:
            g = sp["data"]["geometry"]
            sp["data"]["ground"]["logged_to"] = round(g["axis_depth"] + g["radius"], 3)
    return [{**sp, "seed": seed} for sp in specs]


def confident_wrong(rows: list[dict]) -> tuple[int, int]:
    """(confident wrong causes, cases with effect size > THRESHOLD) of a leave-out run."""
    big = [r for r in rows if isinstance(r["effect_size"], float) and r["effect_size"] > THRESHOLD]
    wrong = [r for r in big if r["grade"] == "named" and family_of(r["named"]) != family_of(r["kind"])]
    return len(wrong), len(big)


def rate_text(k: int, n: int) -> str:
    """'k/n = p % ± s.e. %' (binomial standard error; with k = 0 the rule of three's 95 % upper bound)."""
    if not n:
        return f"{k}/0"
    p = k / n
    extra = f", 95 % upper bound {min(100.0, 300 / n):.1f} % (rule of three)" if k == 0 else ""
    return f"{k}/{n} = {100 * p:.1f} % ± {100 * math.sqrt(p * (1 - p) / n):.1f} % (binomial s.e.{extra})"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--concealed", type=int, default=60, help="number of concealed-physics cases")
    ap.add_argument("--null", type=int, default=30, help="number of null cases (nothing concealed)")
    ap.add_argument("--staged", type=int, default=0,
                    help="number of staged, lined cases (release-before-lining, lining-stiffness, null-staged in turn)")
    ap.add_argument("--yielding", type=int, default=0, help="number of yielding-ground cases (slow: non-linear truth)")
    ap.add_argument("--seed", type=int, default=2024, help="master seed (everything else is drawn from it)")
    ap.add_argument("--seeds", type=int, nargs="+", default=None, metavar="SEED",
                    help="several master seeds, one set of cases each (summaries per seed, then pooled); "
                         "overrides --seed")
    ap.add_argument("--only", nargs="+", default=None, metavar="KIND",
                    help="diagnose only the cases of these kinds (drawn as without it: the same cases, a subset)")
    ap.add_argument("--workers", type=int, default=2, help="worker processes")
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT, help="CSV, one row per case")
    ap.add_argument("--mesh-cache", type=Path, default=None,
                    help="mesh cache folder (default: a temporary one, removed at the end)")
    ap.add_argument("--show", type=int, default=None, metavar="INDEX",
                    help="run only case INDEX (as numbered in the case names) here and print its diagnosis")
    ap.add_argument("--leave-out", action="store_true",
                    help="leave-one-family-out: diagnose each concealed case (strong effects) with its truth's "
                         "family removed from the library; --concealed/--staged/--yielding count the cases")
    ap.add_argument("--logged", action="store_true",
                    help="every case states that boreholes logged its strata to the tunnel's invert (ground: "
                         "logged_to): the same draws (every concealed stratum lies at least 2 m deeper), diagnosed "
                         "with no stratum boundary proposed above it")
    args = ap.parse_args(argv)
    seeds = args.seeds or [args.seed]
    specs = [sp for seed in seeds for sp in make_specs(args, seed)]
    if args.only:
        unknown = sorted(set(args.only) - {sp["kind"] for seed in seeds for sp in make_specs(args, seed)})
        if unknown:
            ap.error(f"--only: no case of kind {', '.join(unknown)} among those drawn")
        specs = [sp for sp in specs if sp["kind"] in args.only]

    work = Path(tempfile.mkdtemp(prefix="geoback-diagacc-"))
    cache = args.mesh_cache or (work / "cache")  # a temporary cache goes with `work`
    os.environ["GEOBACK_CACHE"] = str(cache)  # inherited by the workers
    if args.show is not None:
        try:
            specs = [sp for sp in make_specs(args, seeds[0]) if sp["index"] == args.show]  # by its name's number
            if not specs:  # (a leave-out run drops the nulls: a list position is not a case's number)
                raise SystemExit(f"--show {args.show}: no case bench-{args.show:03d} among the cases these options draw")
            r = run_one(specs[0], str(work), show=True)
        finally:
            shutil.rmtree(work, ignore_errors=True)
        print({k: v for k, v in r.items() if v != ""})
        return 0
    t0 = time.perf_counter()
    rows = []
    try:
        with ProcessPoolExecutor(args.workers, initializer=_init_worker) as pool:
            futures = {pool.submit(run_one, s, str(work)): s for s in specs}
            for fut in as_completed(futures):
                r = fut.result()
                r["seed"] = futures[fut]["seed"]
                rows.append(r)
                eff = r["effect_size"] if isinstance(r["effect_size"], float) else float("nan")
                raw = r["raw_movement"] if isinstance(r["raw_movement"], float) else float("nan")
                mark = "ok " if r["correct"] else "WRONG"
                secs = r["seconds"] if isinstance(r["seconds"], float) else float("nan")
                print(f"[{len(rows):3d}/{len(specs)}] {r['case']:<34} {r['parameter']:<20} {_fmt(r['magnitude']):>9}  "
                      f"effect {eff:7.2f}  raw {raw:7.2f}  -> {r['named']:<20} {r['grade'] or '':<9} {mark} {secs:5.1f} s"
                      + (f"  {r['error']}" if r["error"] else "")
                      + (f"  (seed {r['seed']})" if len(seeds) > 1 else ""), flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    seconds = time.perf_counter() - t0
    write_csv(rows, args.out)
    ok = True
    for seed in seeds:
        mine = [r for r in rows if r["seed"] == seed]
        text, passed = (leave_out_summary if args.leave_out else summary)(mine, seconds if len(seeds) == 1 else
                                                                          sum(r["seconds"] or 0.0 for r in mine))
        ok &= passed
        print()
        print(f"seed {seed}, {args.concealed} concealed + {0 if args.leave_out else args.null} null cases"
              + (f" + {args.staged} staged" if args.staged else "")
              + (f" + {args.yielding} yielding" if args.yielding else "")
              + f", {args.workers} workers; "
              f"rows in {args.out}")
        print(text)
    if len(seeds) > 1 and args.leave_out:
        k, n = confident_wrong(rows)
        passed = n > 0 and k / n <= FLOOR_CONFIDENT_WRONG
        print()
        print(f"pooled over seeds {', '.join(map(str, seeds))}: confident wrong causes {rate_text(k, n)} "
              f"(floor <= {100 * FLOOR_CONFIDENT_WRONG:.0f} %: {'PASS' if passed else 'FAIL'}); total time "
              f"{seconds:.0f} s")
        ok &= passed
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
