"""Bounded work for every physics (issue 23, items 6, 7 and 9).

- 23.7: the size guard and the memory estimate are each physics' own (``meshsize.Work``): Mohr-Coulomb
  and staged runs need 3-4 times the elastic model's memory per DOF, so they are allowed
  proportionally fewer DOFs, refused beyond unless --allow-large, announced by validate; the
  estimate holds to within 1.5x of the peak memory measured on a real run; a plastic run says where it
  is (stage k of n, increment, Newton iteration) once it has run a few seconds.
- 23.6: the time limit (``geoback.case.budget``): past it a fit stops with its best point, a diagnosis
  with what it found, and work that cannot stop early is cut after its grace with a located message;
  the commands write what was found and exit 1 with words.
- 23.9: a Mohr-Coulomb fit is never lost at its end: a point without a solution with its
  sensitivities is a rejected step (caveat 'model-unsolved'), the assessment reuses the accepted
  point's run, a discretisation-error check the finer model cannot solve is skipped and said so; a
  tiny first release (beta = 1e-6) is one exact elastic step.

Time is never asserted: the limit is tested on a clock that counts calls (``budget.clock``).
"""
from __future__ import annotations

import copy
import math
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from geoback.case import budget
from geoback.case import meshsize
from geoback.case.loading import LoadedCase, case_from_data, load_case
from geoback.case.meshsize import Work, estimate, mesh_inputs
from geoback.errors import CaseError, ForwardFailure, GeobackError, TimeLimit
from geoback.inference.estimate import Settings, fit
from geoback.inference.identification import prepare
from geoback.physics.factory import make_simulation
from measure import run_cli

ROOT = Path(__file__).resolve().parents[1]
CASES = ROOT / "cases"
PLASTIC = CASES / "plastic-tunnel.yaml"
STAGED = CASES / "staged-tunnel.yaml"
TOLERANCE = 1.5  # estimate within this factor of the measured peak


def _data(path: Path) -> dict:
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    for ins in data["instruments"]:
        if "readings_file" in ins:
            ins["readings_file"] = str(CASES / ins["readings_file"])
    return data


def _write(tmp_path: Path, data: dict, name: str = "case.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


class Ticks:
    """A clock that advances one second each time it is read: limits in counts of reads."""

    def __init__(self):
        self.t = 0.0

    def __call__(self) -> float:
        self.t += 1.0
        return self.t


# ------------------------------------------------------------------------------------------- 23.7
def test_work_of_each_physics():
    plastic, staged, paper = (load_case(p).case for p in (PLASTIC, STAGED, CASES / "tunnel-paper.yaml"))
    w = Work.of(plastic)
    assert w.physics == "mohr-coulomb" and w.increments == 5 + 3 + 2 and w.check  # releases 0.5, 0.8, 1.0
    assert Work.of(staged).physics == "staged" and Work.of(paper) == Work()
    # per DOF a Mohr-Coulomb run needs several times the elastic model's memory: fewer DOFs for the same memory
    assert w.limit_dofs(500_000) < 0.3 * 500_000 and Work().limit_dofs(500_000) == 500_000
    assert w.forward_bytes(1e5) > 3 * Work().forward_bytes(1e5) - 3 * meshsize.RUN_BASE_BYTES


def test_mohr_coulomb_guard_refuses_what_elastic_ground_would_pass(tmp_path):
    """The issue's cases: Mohr-Coulomb at 463 k DOFs ran out of 5.4 GB where ~1.7 GB was announced, and
    at 83 k DOFs took 1.3 GB against ~420 MB. Now a Mohr-Coulomb mesh is refused beyond ~136 k DOFs
    with its own memory in the message; the same mesh with elastic ground is accepted."""
    data = _data(PLASTIC)
    data["mesh"] = {"size_tunnel": 0.02, "size_far": 0.4}  # ~150 k DOFs: under the elastic limit
    path = _write(tmp_path, data)
    with pytest.raises(CaseError) as info:
        load_case(path)
    message = str(info.value)
    assert re.search(r"mesh\.size_far: expected mesh sizes giving at most 136,000 DOFs for Mohr-Coulomb ground "
                     r"\(~1\.8 GB to run\), found sizes giving about 1\d\d,000 DOFs, ~\d\.\d GB .*or pass "
                     r"--allow-large$", message), message
    assert load_case(path, allow_large=True).allow_large
    elastic = copy.deepcopy(data)
    for layer in elastic["ground"]["layers"]:
        for key in ("model", "c", "phi", "psi"):
            layer.pop(key, None)
    load_case(_write(tmp_path, elastic, "elastic.yaml"))  # accepted
    # the first case: ~4 times the memory announced
    data["mesh"] = {"size_tunnel": 0.012, "size_far": 0.25}
    est = estimate(mesh_inputs(case_from_data(data, allow_large=True)), Work.of(case_from_data(data, allow_large=True)))
    assert est.dofs > 300_000 and est.run_bytes > 4e9


def test_validate_announces_the_cost_of_each_physics():
    run = run_cli(["validate", PLASTIC], ROOT / "tests")
    assert run.returncode == 0, run.stderr
    assert re.search(r"cost of `geoback run`: ~\d+ MB of memory at most \(with its discretisation-error check on a "
                     r"mesh twice as fine, about [\d,]+ DOFs\); Mohr-Coulomb ground: up to 10 load increments a "
                     r"forward run \(about 31 factorisations", run.stdout), run.stdout


@pytest.mark.parametrize("case", [PLASTIC, STAGED], ids=["mohr-coulomb", "staged"])
def test_memory_estimate_within_tolerance_of_a_real_run(case, tmp_path):
    """`geoback run` in a fresh interpreter (its fit, the discretisation-error check on the mesh twice as
    fine, the outputs): its peak resident memory against the estimate validate announces."""
    est = estimate(mesh_inputs(load_case(case).case), Work.of(load_case(case).case))
    env = {**__import__("os").environ, "GEOBACK_CACHE": str(tmp_path / "cache")}
    run = run_cli(["run", case, "-q", "--out", tmp_path / "out"], tmp_path, env=env)
    assert run.returncode == 0, run.stderr
    if math.isnan(run.peak_bytes):
        pytest.skip("no /proc: peak memory not measured")
    ratio = est.run_bytes / run.peak_bytes
    print(f"{case.name}: estimate {est.run_bytes / 1e6:.0f} MB, measured {run.peak_bytes / 1e6:.0f} MB ({ratio:.2f})")
    assert 1 / TOLERANCE <= ratio <= TOLERANCE, (est.run_bytes, run.peak_bytes)


def _plastic_small(**changes) -> LoadedCase:
    data = _data(PLASTIC)
    data["mesh"] = {"size_tunnel": 1.0, "size_far": 10.0}
    data.update(changes)
    return LoadedCase(case_from_data(data), None, {})


def test_plastic_run_says_where_it_is(monkeypatch):
    """Progress lines through geoback.case.budget: stage k of n, the increment, Newton iterations (shown
    once a run has gone FIRST_WORDS seconds: here from the start), and a closing line."""
    import geoback.physics.plastic as plastic

    monkeypatch.setattr(plastic, "FIRST_WORDS", 0.0)
    monkeypatch.setattr(plastic, "EVERY", 0.0)
    sim = make_simulation(_plastic_small())
    lines = []
    with budget.limited(None, say=lines.append):
        sim.predict(sim.quantities())
    assert any(re.search(r"forward run 1: stage 3 of 3 \(final\), increment \d+ \(lambda [\d.]+\), "
                         r"(Newton iteration \d+, residual|converged in \d+ Newton)", line) for line in lines), lines
    assert any("stage 1 of 3 (face-near)" in line for line in lines)
    assert re.search(r"forward run 1 done: \d+ increments, \d+ Newton iterations, \d+ factorisations", lines[-1])
    quiet = []
    with budget.limited(None, say=quiet.append):  # a short run (FIRST_WORDS at its default) says nothing
        monkeypatch.setattr(plastic, "FIRST_WORDS", 1e9)
        sim.release()
        sim.predict(sim.quantities())
    assert quiet == []


# ------------------------------------------------------------------------------------------- 23.6
def test_time_limit_parsing():
    assert budget.parse_seconds("90 min") == 5400 and budget.parse_seconds("2 h") == 7200
    assert budget.parse_seconds("none") is None and budget.parse_seconds("0") is None
    assert budget.parse_seconds(30) == 30
    for bad in ("soon", "-5", "nan", "1 fortnight"):
        with pytest.raises(GeobackError, match="--time-limit"):
            budget.parse_seconds(bad)


def test_past_the_limit_a_fit_keeps_its_best_point(monkeypatch):
    """The limit passes during the fit: it stops with the best accepted point (status not converged, the
    reason and a 'time-limit' warning say why), not with an error."""
    analysis = prepare(_plastic_small())
    ticks = Ticks()
    monkeypatch.setattr(budget, "clock", ticks)
    with budget.limited(1e9):  # how often the whole fit reads the clock
        whole = fit(analysis.misfit, analysis.settings)
    analysis.simulation.release()
    half = int(ticks.t // 2)
    monkeypatch.setattr(budget, "clock", Ticks())
    with budget.limited(half):  # half way through
        res = fit(analysis.misfit, analysis.settings)
        assert budget.reached()
    assert whole.status == "converged" and not whole.warnings
    assert res.status == "not converged" and "time limit" in res.reason and res.moved
    assert re.match(r"the fit was stopped at the time limit of [\d.]+ (s|min) in iteration \d+ with the best point "
                    r"it had reached", dict(res.warnings)["time-limit"])
    accepted = [h for h in res.history if h.accepted]
    assert res.J == min(h.J for h in accepted) and len(accepted) >= 2


def test_past_the_grace_a_forward_run_stops_where_it_is(monkeypatch):
    """Work that cannot stop early (a forward run) is cut after the limit's grace: TimeLimit names the
    run, stage, increment and what the command was doing."""
    sim = make_simulation(_plastic_small())
    monkeypatch.setattr(budget, "MIN_GRACE", 0.0)
    monkeypatch.setattr(budget, "clock", Ticks())
    with pytest.raises(TimeLimit) as info, budget.limited(20):
        budget.say("refitting with a stiffness gradient")
        sim.predict(sim.quantities())
    message = str(info.value)
    assert re.match(r"stopped at the time limit of 20 s \(and 5 s of grace to finish\): forward run 1 \(Mohr-Coulomb\) "
                    r"at stage \d of 3 \(\S+\), increment \d+ \(lambda [\d.e-]+\)(, Newton iteration \d+)? while "
                    r"refitting with a stiffness gradient; raise it with --time-limit", message), message
    assert info.value.exit_code == 1


def test_run_and_diagnose_past_the_limit_write_what_they_found(tmp_path):
    """The commands: a limit the work cannot meet stops it with the results so far written, a warning
    line and exit code 1 (no traceback, no hang)."""
    env = {**__import__("os").environ, "GEOBACK_CACHE": str(tmp_path / "cache")}
    run = run_cli(["run", CASES / "tunnel-paper.yaml", "-q", "--out", tmp_path / "r", "--time-limit", "1e-6"],
                  tmp_path, env=env)
    assert run.returncode == 1, run.stderr
    assert "warning: the identification stopped at the time limit of 1e-06 s" in run.stderr, run.stderr
    assert (tmp_path / "r" / "summary.json").exists() and "Traceback" not in run.stderr
    diag = run_cli(["diagnose", CASES / "tunnel-paper.yaml", "-q", "--no-plots", "--out", tmp_path / "d",
                    "--time-limit", "1e-6"], tmp_path, env=env)
    assert diag.returncode == 1, diag.stderr
    assert "warning: the diagnosis stopped at the time limit" in diag.stderr and "Traceback" not in diag.stderr
    assert (tmp_path / "d" / "diagnosis.json").exists()
    bad = run_cli(["run", CASES / "tunnel-paper.yaml", "--time-limit", "soon"], tmp_path, env=env)
    assert bad.returncode == 2 and bad.stderr.startswith("error: --time-limit: expected a time"), bad.stderr


# ------------------------------------------------------------------------------------------- 23.9
def test_tiny_first_release_is_one_exact_elastic_step():
    """beta = 1e-6 in the first stage: the ground is elastic there, and Newton's residual test against
    so small a release is below rounding (it failed in its first increment). One linear step now."""
    data = _data(PLASTIC)
    data["mesh"] = {"size_tunnel": 1.0, "size_far": 10.0}
    data["construction"]["stages"][0]["release"] = 1e-6
    sim = make_simulation(LoadedCase(case_from_data(data), None, {}))
    run = sim.solution(sim.quantities(), ["E[marl]"])
    c = run.result.counters
    assert c.elastic_steps >= 1 and run.result.schedule[0] == (1.0,)
    first = [log for log in run.result.increments if log.stage == 1]
    assert len(first) == 1 and first[0].converged and first[0].plastic_points == 0
    assert np.all(np.isfinite(run.du)) and np.all(np.isfinite(run.u))


def test_a_point_without_sensitivities_is_a_rejected_step(monkeypatch):
    """J is computed at a trial point but its sensitivities are not (the model fails there when asked
    again): the step is rejected, the fit goes on from its best point and says so."""
    analysis = prepare(_plastic_small())
    misfit = analysis.misfit
    evaluate = type(misfit).evaluate
    failed = []

    def flaky(self, p, jacobian=False):
        if jacobian and not failed and not np.allclose(p, analysis.parameters.initial):
            failed.append(np.array(p))
            raise ForwardFailure("no solution at increment 17 of stage 3")
        return evaluate(self, p, jacobian)

    monkeypatch.setattr(type(misfit), "evaluate", flaky)
    res = fit(misfit, Settings(max_iterations=8))
    assert failed and res.moved and np.isfinite(res.J)
    assert "model-unsolved" in dict(res.warnings)
    assert any(np.array_equal(h.p, failed[0]) and not h.accepted and h.J == np.inf for h in res.history)


def test_the_assessment_reuses_the_accepted_run():
    """After rejected trials the simulation's last run is elsewhere; the accepted point's sensitivities
    are asked for again (conclude, outputs) and come from the run kept, not from a new solve."""
    sim = make_simulation(_plastic_small())
    values = sim.quantities()
    names = ["E[marl]", "c[marl]"]
    a = sim.predict(values, names, sensitivities=True).A
    sim.predict(dict(values, **{"E[marl]": 50_000.0}))  # a trial point
    sim.predict(dict(values, **{"E[marl]": 30_000.0}))  # another
    runs = sim.counters.forward_runs
    again = sim.predict(values, names, sensitivities=True).A
    assert sim.counters.forward_runs == runs and np.array_equal(a, again)


def test_discretisation_check_without_solution_keeps_the_fit(monkeypatch):
    """The check's run on the mesh twice as fine has no solution (Mohr-Coulomb on a finer mesh: the
    issue's run lost its converged fit with exit code 2 there): skipped, said so, the fit kept."""
    import geoback.physics.factory as factory
    from geoback.inference.identification import identify
    from geoback.physics.plasticity.incremental import NonConvergence

    analysis = prepare(_plastic_small())
    made = factory.make_simulation

    def failing(loaded, **kwargs):
        sim = made(loaded, **kwargs)

        def no_solution(*a, **k):
            raise NonConvergence(10, 3, 0.8797, 0.8799, 99.8, 15, "no convergence in 15 iterations", 1e-10)

        sim.predict = no_solution
        return sim

    monkeypatch.setattr(factory, "make_simulation", failing)
    res = identify(analysis, mesh_error="check", profile="none")
    assert res.fit.moved and res.mesh_error.skipped.startswith("the model could not be solved on the mesh 2 times finer")
    assert "model-unsolved" in {c.code for c in res.caveats}


def test_identify_reports_the_fit_warnings_as_caveats(monkeypatch):
    """The library's identify() stopped at the time limit says so in its caveats, as `geoback run` does
    (one place: ``caveats.fit_caveats`` turns ``Fit.warnings`` into caveats for every concluded result).
    The limit is set at half the clock reads of the whole identification, so that it passes during the
    fit (a fixed 200 reads was more than the whole identification makes, and no limit was reached)."""
    from geoback.inference.identification import identify

    analysis = prepare(_plastic_small())
    ticks = Ticks()
    monkeypatch.setattr(budget, "clock", ticks)
    with budget.limited(1e9):
        whole = identify(analysis, profile="none")
    analysis.simulation.release()
    assert "time-limit" not in {c.code for c in whole.caveats}
    monkeypatch.setattr(budget, "clock", Ticks())
    with budget.limited(int(ticks.t // 2)):
        res = identify(analysis, profile="none")
        assert budget.reached()
    codes = [c.code for c in res.caveats]
    assert codes.count("time-limit") == 1 and res.fit.status == "not converged"
    message = dict((c.code, c.message) for c in res.caveats)["time-limit"]
    assert message == dict(res.fit.warnings)["time-limit"] and "it had not converged" in message


def test_nan_in_a_matrix_is_refused_not_factorised():
    """SuperLU factorised a matrix with NaN silently and its solves printed BLAS errors ('On entry to
    DGEMV parameter number 2 had an illegal value') on stderr: refused as singular now."""
    import scipy.sparse as sp

    from geoback.physics.plasticity.linear import LU, Counters, SingularMatrix

    A = sp.csr_matrix(np.array([[2.0, 1.0], [1.0, np.nan]]))
    with pytest.raises(SingularMatrix, match="not finite"):
        LU(Counters(), "scipy").factorise(A)
    lu = LU(Counters(), "scipy").factorise(sp.csr_matrix(np.eye(2)))
    with pytest.raises(SingularMatrix, match="not finite"):
        lu.solve(np.array([1.0, np.inf]))


def test_singular_tangent_is_refused_not_solved():
    """A tangent with a mechanism (rank 853 of 857, from a Mohr-Coulomb diagnosis' layer-boundary refit
    of a fuzzed case): SuperLU factorised it without a word, its solves were off by 0.4 % and printed BLAS
    errors on stderr. Refused now (the Newton iteration then fails cleanly and the increment is halved)."""
    import scipy.sparse as sp

    from geoback.physics.plasticity.linear import LU, Counters, SingularMatrix

    A = sp.load_npz(ROOT / "tests" / "data" / "singular-tangent.npz").tocsr()
    with pytest.raises(SingularMatrix, match="singular to working precision"):
        LU(Counters(), "scipy").factorise(A)
    LU(Counters(), "scipy").factorise(A + sp.eye(A.shape[0], format="csr") * abs(A).max())  # regular: accepted
