"""Data worth for telling two hypotheses apart (geoback.worth.discrimination): the linearised growth of
the wrong hypothesis' chi-square a candidate brings, against refitting it to the readings the true
one predicts (existing and candidate together)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy import stats

from conftest import CASES
from geoback.case.loading import LoadedCase, case_from_data
from geoback.case.schema import Parameter
from geoback.worth.design import candidate_blocks
from geoback.worth.discrimination import discriminate
from geoback.inference.estimate import fit
from geoback.inference.identification import prepare
from geoback.inference.misfit import Data, Misfit
from geoback.physics.factory import make_simulation


def gradient_case(candidates: list[dict]) -> dict:
    """The concealed modulus-gradient case (its readings files by absolute path) with these candidates."""
    data = yaml.safe_load((CASES / "concealed" / "stiffness-gradient.yaml").read_text())
    for ins in data["instruments"]:
        if "readings_file" in ins:
            ins["readings_file"] = str((CASES / "concealed" / ins["readings_file"]).resolve())
    data["design"] = {"objective": "parameters", "candidates": candidates}
    return data


@pytest.fixture(scope="module")
def gradient_vs_anisotropy(tmp_path_factory):
    """Readings of a concealed modulus gradient; a = the gradient, b = cross-anisotropy, both fitted."""
    data = gradient_case([
        {"name": "I3", "kind": "inclinometer", "x": 9.0, "toe_depth": 30.0, "spacing": 1.5, "stations": 19,
         "sigma": 0.0003, "vary": {"x": [4.0, 6.0, 14.0, 20.0]}},
        {"name": "P", "kind": "points", "points": [[0.0, 0.0]], "components": ["ux"], "sigma": 0.0003,
         "vary": {"points": [[[4.0, -8.0]], [[4.0, -12.0]], [[8.0, -16.0]], [[0.0, -20.0]]]}}])
    loaded = LoadedCase(case_from_data(data), tmp_path_factory.mktemp("disc") / "case.yaml", {})
    an = prepare(loaded)
    f0 = fit(an.misfit, an.settings)
    ma = an.misfit.extended([Parameter(name="Egrad[clay]", initial=0.0)], start=f0.p)
    mb = an.misfit.extended([Parameter(name="n[clay]", initial=1.0)], start=f0.p)
    fa, fb = fit(ma, an.settings), fit(mb, an.settings)
    cands = candidate_blocks(loaded, an.simulation.stages[-1])
    return loaded, an, (ma, fa), (mb, fb), [c.name for _, c, _ in cands], [b for _, _, b in cands]


def test_separation_agrees_with_refitting_the_wrong_hypothesis(gradient_vs_anisotropy):
    loaded, an, (ma, fa), (mb, fb), names, blocks = gradient_vs_anisotropy
    D = discriminate(("a modulus gradient", ma, fa.p), ("anisotropy", mb, fb.p), blocks, names)
    actual = []
    for blk in blocks:  # a true: b refitted to a's readings with and without the candidate's
        sim = make_simulation(loaded, blocks=list(an.simulation.survey.blocks) + [blk])
        xa = sim.predict(ma.values(fa.p)).x
        both = Misfit(sim, Data.build(sim.survey.blocks, xa, set()), mb.parameters, mb.base_values, "full")
        f2 = fit(both, an.settings, p0=fb.p)
        alone = mb.with_measured(xa[:an.misfit.m])
        f1 = fit(alone, an.settings, p0=fb.p)
        actual.append(both.J(f2.p) - alone.J(f1.p))
    actual = np.array(actual)
    incl = [k for k, n in enumerate(names) if n.startswith("I3")]
    # where b barely moves to follow the candidate (inclinometers) the linearisation is exact to 1 %
    np.testing.assert_allclose(D.lam_ab[incl], actual[incl], rtol=0.03)
    assert actual[incl].min() > 5  # these candidates do separate the two
    # points where b bends to follow them: the linearisation overstates (measured up to 1.6x), the ranking holds
    assert np.all(D.lam_ab >= 0.9 * actual - 1e-9)
    assert np.argmax(D.lam_ab) == np.argmax(actual)
    assert stats.spearmanr(D.lam_ab, actual).statistic > 0.9
    # a horizontal reading on the symmetry axis reads nothing under either hypothesis
    k = names.index("P-4")
    assert D.lam_ab[k] < 1e-12 and D.lam_ba[k] < 1e-12 and D.power[k] == pytest.approx(0.05)
    # power is the non-central chi-square(1) tail at the 5 % critical value
    s = D.separation
    np.testing.assert_allclose(D.power, stats.ncx2.sf(stats.chi2.isf(0.05, 1), 1, np.maximum(s, 1e-12)))
    assert D.as_dict()["candidates"][0]["name"] == names[0]


def test_identical_hypotheses_are_not_separated(gradient_vs_anisotropy):
    loaded, an, (ma, fa), _, names, blocks = gradient_vs_anisotropy
    D = discriminate(("a", ma, fa.p), ("a again", ma, fa.p), blocks, names)
    assert np.all(D.separation < 1e-9)


def test_design_separate_ranks_candidates_between_the_leading_hypotheses(tmp_path):
    """`geoback design --separate` on a concealed modulus gradient: the diagnosis' two leading
    hypotheses, each candidate's power in design.md, design.csv and design.json."""
    import json

    from typer.testing import CliRunner

    from geoback.commands.cli import app

    data = gradient_case([
        {"name": "I3", "kind": "inclinometer", "x": 9.0, "toe_depth": 30.0, "spacing": 1.5, "stations": 19,
         "sigma": 0.0003, "vary": {"x": [4.0, 20.0]}},
        {"name": "P", "kind": "points", "points": [[0.0, -20.0]], "components": ["ux"], "sigma": 0.0003}])
    path = tmp_path / "case.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    result = CliRunner().invoke(app, ["design", str(path), "--separate", "--out", str(tmp_path / "out"),
                                      "--no-plots"])
    assert result.exit_code == 0, result.output
    out = json.loads((tmp_path / "out" / "design.json").read_text())["separation"]
    assert "increasing with depth" in out["a"] + out["b"]
    power = {c["name"]: c["power"] for c in out["candidates"]}
    assert power["I3-x4"] > 0.9 > power["I3-x20"]  # near the tunnel the two differ; far out they do not
    assert power["P"] == pytest.approx(0.05)  # a horizontal reading on the symmetry axis tells nothing
    assert "best to tell" in result.output
    assert "separation_power" in (tmp_path / "out" / "design.csv").read_text().splitlines()[0]
    assert "## Telling" in (tmp_path / "out" / "design.md").read_text()


def test_design_separate_says_when_there_is_nothing_to_tell_apart(tmp_path):
    """The shipped staged-forecast case: diagnose refits no hypothesis, and design says so."""
    import json

    from typer.testing import CliRunner

    from geoback.commands.cli import app

    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["design", str(CASES / "staged-forecast.yaml"), "--separate", "--out", str(out),
                                      "--no-plots"])
    assert result.exit_code == 0, result.output
    assert "nothing to tell apart" in result.output
    assert "nothing to tell apart" in (out / "design.md").read_text()
    assert json.loads((out / "design.json").read_text())["separation"]["candidates"] == []
    assert "separation" not in (out / "design.csv").read_text().splitlines()[0]
