"""The library checks what the command line checks (issue 23): called as a user would call it
(docs/examples style), never through the CLI."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

import geoback
from geoback.errors import GeobackError

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "cases" / "tunnel-paper.yaml"


def _shipped_with(tmp_path: Path, name: str, change) -> Path:
    """A shipped case with one change (`change(data)`), written to tmp_path with its readings files
    still found."""
    import yaml

    data = yaml.safe_load((ROOT / "cases" / name).read_text())
    change(data)
    for ins in data["instruments"]:
        if ins.get("readings_file"):
            ins["readings_file"] = str(ROOT / "cases" / ins["readings_file"])
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return path


def _snapshot(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.stat().st_mtime_ns for p in sorted(folder.rglob("*"))}


@pytest.mark.parametrize("target", [".", "..", ""])
def test_run_case_refuses_the_callers_folder(tmp_path, monkeypatch, target):
    """`geoback.run_case(loaded, ".")` replaced the current folder by a new one holding the results:
    os.getcwd() then failed in the caller's process. Now refused before any work, folder untouched."""
    work = tmp_path / "work"
    work.mkdir()
    (work / "notes.txt").write_text("mine")
    (work / "sub").mkdir()
    monkeypatch.chdir(work)
    loaded = geoback.load_case(PAPER)
    before_id, before = os.stat(work).st_ino, _snapshot(work)
    with pytest.raises(GeobackError, match="expected"):
        geoback.run_case(loaded, target)
    assert os.getcwd() == str(work) and os.stat(work).st_ino == before_id
    assert _snapshot(work) == before


def test_run_case_writes_a_results_subfolder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "notes.txt").write_text("mine")
    res = geoback.run_case(geoback.load_case(PAPER), "out")
    assert res.fit.status == "converged"
    assert (tmp_path / "out" / "summary.json").is_file() and (tmp_path / "notes.txt").read_text() == "mine"
    assert os.getcwd() == str(tmp_path)


@pytest.mark.parametrize("alpha", [0, 0.0, 1, -1, float("nan"), float("inf"), "0.05"])
def test_diagnose_refuses_a_level_outside_0_1(alpha):
    """`diagnose --alpha 0` ran until killed (every hypothesis 'significant' at no level, refits without
    end) and -1 or nan ended in scipy's words; the library refuses them at once."""
    with pytest.raises(GeobackError, match="between 0 and 1"):
        geoback.diagnose(geoback.load_case(PAPER), alpha=alpha)


def test_diagnose_cli_refuses_alpha_before_any_work(tmp_path):
    from measure import run_cli

    for value in ("0", "-1", "nan", "1.5"):
        run = run_cli(["diagnose", PAPER, "--alpha", value, "--out", tmp_path / "d"], tmp_path)
        assert run.returncode == 2 and "--alpha: expected a significance level between 0 and 1" in run.stderr, \
            run.stderr
        assert "Traceback" not in run.stderr and not (tmp_path / "d").exists()


def test_an_error_scale_prior_of_huge_dof_is_refused_located(tmp_path):
    """An inverse-chi2 prior worth 1e20 readings ended in a traceback in run_case; it is a known
    scale, refused at load with its location."""
    path = _shipped_with(tmp_path, "tunnel-paper-error-scales.yaml", lambda d: d.update(error_scales=[
        {"instruments": ["I1"], "prior": {"shape": "inverse-chi2", "dof": 1e20}}]))
    with pytest.raises(GeobackError) as info:
        geoback.load_case(path)
    assert "error_scales[0].prior.dof" in str(info.value) and "scale: known" in str(info.value)


def test_simulate_seed_must_be_a_whole_number_0_or_above(tmp_path):
    from measure import run_cli

    run = run_cli(["simulate", PAPER, "--noise", "--seed", "-1", "--readings-out", tmp_path / "r.csv"], tmp_path)
    assert run.returncode == 2 and run.stderr.startswith("error: --seed: expected a whole number 0 or above, found -1")
    assert not (tmp_path / "r.csv").exists()


def test_a_forecast_chord_whose_ends_coincide_is_refused_by_validate(tmp_path):
    """`validate` said valid and `run` refused: a convergence forecast between one point and itself."""
    chord = {"name": "chord", "kind": "convergence", "points": [[4.0, -15.0], [4.0, -15.0]], "stage": "lined"}
    path = _shipped_with(tmp_path, "staged-forecast.yaml", lambda d: d["forecasts"].append(chord))
    with pytest.raises(GeobackError) as info:
        geoback.load_case(path)
    index = len(geoback.load_case(ROOT / "cases" / "staged-forecast.yaml").case.forecasts)
    assert f"forecasts[{index}].points" in str(info.value) and "two distinct points" in str(info.value)
