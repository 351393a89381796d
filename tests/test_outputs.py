"""Result files of `geoback run`: reproducible byte for byte, replaced as a whole set, always written."""
from __future__ import annotations

import csv
import io
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

import geoback.reports.resultsets
from geoback.case.loading import load_case
from geoback.inference.explore import explore
from geoback.inference.identification import identify, prepare
from geoback.reports.report import write_run
from geoback.commands.run import run_case

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "cases" / "tunnel-paper.yaml"
GEOBACK = [sys.executable, "-m", "geoback.commands.cli"]

TABLES = ["parameters.csv", "covariance.csv", "correlation.csv", "eigen.csv", "information_density.csv",
          "readings.csv", "iterations.csv"]
VOLATILE = ("timings_s", "platform")  # legitimately differ between two runs


@pytest.fixture()
def cache(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv("GEOBACK_CACHE", str(folder))
    return folder


def cli(*args, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run(GEOBACK + [str(a) for a in args], capture_output=True, text=True, cwd=cwd,
                          env=dict(os.environ), timeout=300)


def stable_summary(path: Path) -> dict:
    data = json.loads(path.read_text())
    for key in VOLATILE:
        data.pop(key, None)
    return data


def case_variant(tmp_path: Path, name: str, **fit) -> Path:
    """A copy of the paper case (whatever its current content) with fit settings overridden."""
    data = yaml.safe_load(PAPER.read_text())
    data["fit"] = {**data.get("fit", {}), **fit}
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


# (i) reproducibility --------------------------------------------------------------------------


def test_two_runs_give_identical_files(tmp_path, cache):
    """A cold run (gmsh meshes) and a warm run (mesh from the cache) write the same bytes."""
    first, second = tmp_path / "first", tmp_path / "second"
    for out in (first, second):
        r = cli("run", PAPER, "--out", out, "-q")
        assert r.returncode == 0, r.stderr
    for name in TABLES + ["report.md", "field.vtu"]:
        assert (first / name).read_bytes() == (second / name).read_bytes(), f"{name} differs between runs"
    a, b = stable_summary(first / "summary.json"), stable_summary(second / "summary.json")
    differing = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
    assert not differing, f"summary.json fields differ between identical runs: {differing}"
    assert a["status"] == "converged"


# (ii) atomic writes ---------------------------------------------------------------------------


def _parse(path: Path):
    """Parse a result file completely; a torn file raises."""
    text = path.read_text()
    if path.suffix == ".json":
        return json.loads(text)
    if path.suffix == ".csv":
        rows = list(csv.reader(io.StringIO(text)))
        assert rows and all(len(r) == len(rows[0]) for r in rows), f"{path.name}: ragged CSV"
        assert text.endswith("\n"), f"{path.name}: truncated"
        return rows
    if path.suffix == ".vtu":
        import meshio

        return meshio.read(path)
    return text


def _same(path: Path, reference: Path) -> bool:
    if path.name == "summary.json":
        return stable_summary(path) == stable_summary(reference)
    return path.read_bytes() == reference.read_bytes()


class Interrupted(Exception):
    pass


def test_interrupted_run_leaves_old_or_new_set(tmp_path, cache, monkeypatch):
    """Fail the n-th file-system step of writing a run into a folder holding an older run's results
    (each write of a file, each link of a carried-over file, each rename, the swap), for every n:
    afterwards the folder holds exactly the old set or, once the swap is done, exactly the new one;
    every file parses, and no temporary file or folder is left behind."""
    weighting = yaml.safe_load(PAPER.read_text()).get("fit", {}).get("weighting", "full")
    old_case = case_variant(tmp_path, "old.yaml", max_iterations=2,  # an older run that differs in every file
                            weighting="full" if weighting == "identity" else "identity")
    old, new = tmp_path / "old", tmp_path / "new"
    run_case(load_case(old_case), old)
    (old / "notes.txt").write_text("the user's own notes\n")  # not geoback's: carried over
    analysis = prepare(load_case(PAPER))
    result = identify(analysis)  # identified once; written again for every n below
    exploration = explore(analysis.misfit, result, ("field",))  # writing reads it and runs no model
    write_run(result, new, exploration)
    names = sorted(p.name for p in new.iterdir() if not p.name.startswith("."))
    assert sorted(p.name for p in old.iterdir() if not p.name.startswith(".")) == sorted(names + ["notes.txt"])
    for name in names:
        assert not _same(old / name, new / name), f"{name}: old and new runs must differ for this test"

    real = {"replace": os.replace, "link": os.link, "rename": os.rename, "swap": geoback.reports.resultsets._swap}
    state = {"left": -1, "steps": 0, "swapped": False}

    def step():
        state["steps"] += 1
        if state["left"] == 0:
            raise Interrupted("killed")
        state["left"] -= 1

    def failing(name):
        def wrapper(*args, **kwargs):
            step()
            result = real[name](*args, **kwargs)
            state["swapped"] |= name == "swap"
            return result
        return wrapper

    for name in ("replace", "link", "rename"):
        monkeypatch.setattr(geoback.reports.resultsets.os, name, failing(name))
    monkeypatch.setattr(geoback.reports.resultsets, "_swap", failing("swap"))
    out = tmp_path / "probe"
    shutil.copytree(old, out)
    write_run(result, out, exploration)  # count the steps of a whole write
    total = state["steps"]
    assert total > len(names)
    for n in range(total + 1):
        out = tmp_path / f"run{n}"
        shutil.copytree(old, out)
        state.update(left=n, steps=0, swapped=False)
        try:
            write_run(result, out, exploration)
        except Interrupted:
            assert n < total
        swapped = state["swapped"]  # the new set is in place once the swap is done, not before
        present = sorted(p.name for p in out.iterdir() if not p.name.startswith("."))
        assert present == sorted(names + ["notes.txt"]), f"after {n} steps: files {present}"
        assert (out / "notes.txt").read_text() == "the user's own notes\n"
        reference = new if swapped else old
        for name in names:
            _parse(out / name)
            assert _same(out / name, reference / name), \
                f"after {n} of {total} steps: {name} is not the {'new' if swapped else 'old'} version"
        leftovers = [p.name for p in tmp_path.iterdir() if p.name.startswith(f".run{n}")]
        assert not leftovers, f"after {n} steps: left behind {leftovers}"
        assert geoback.reports.resultsets.check_result_set(out, "run") == [] or not swapped
    monkeypatch.undo()


# (iii) a fit that runs out of iterations ------------------------------------------------------


def test_max_iterations_still_writes_everything(tmp_path, cache):
    case = case_variant(tmp_path, "short.yaml", max_iterations=1)
    out = tmp_path / "out"
    r = cli("run", case, "--out", out)
    assert r.returncode == 1, r.stdout + r.stderr
    assert "not converged" in r.stdout + r.stderr
    for name in TABLES + ["report.md", "summary.json", "field.vtu"]:
        assert (out / name).is_file(), name
        _parse(out / name)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "not converged"
    assert summary["iterations"] == 1
    assert "maximum number of iterations" in summary["stop_reason"]
    assert "did not converge" in (out / "report.md").read_text()
    with open(out / "iterations.csv") as fh:
        assert len(list(csv.DictReader(fh))) >= 1
