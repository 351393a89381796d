"""`geoback batch`: many cases on a local process pool or a Dask cluster, one summary.csv."""
from __future__ import annotations

import csv
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from geoback.commands.batch import collect_cases, output_folders, run_batch, summary_table
from geoback.errors import GeobackError

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "cases" / "tunnel-paper.yaml"
GEOBACK = [sys.executable, "-m", "geoback.commands.cli"]


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("cache")


@pytest.fixture(scope="module")
def env(cache):
    return dict(os.environ, GEOBACK_CACHE=str(cache))


def cli(*args, env, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run(GEOBACK + [str(a) for a in args], capture_output=True, text=True, cwd=cwd,
                          env=env, timeout=600)


def read_summary(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def estimate(row: dict, base: str) -> float:
    """The estimate of parameter `base` (named E or E[layer], whichever the case uses)."""
    values = [v for k, v in row.items() if k == base or k.startswith(base + "[")]
    values = [v for v in values if v != ""]
    assert len(values) == 1, (base, row)
    return float(values[0])


@pytest.fixture(scope="module")
def cases_dir(tmp_path_factory):
    """The paper case, a renamed copy starting elsewhere, and a broken case."""
    folder = tmp_path_factory.mktemp("cases")
    shutil.copy(PAPER, folder / "a-paper.yaml")
    data = yaml.safe_load(PAPER.read_text())
    data["name"] = "paper-copy"
    for p in data["parameters"]:
        if p["name"].startswith("E"):
            p["initial"] = "7 MPa"
        elif p["name"].startswith("K0"):
            p["initial"] = 0.8
    (folder / "b-copy.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    (folder / "c-broken.yaml").write_text("name: broken\ngeometry: {radius: 3.0}\n")
    (folder / "notes.txt").write_text("not a case\n")
    return folder


@pytest.fixture(scope="module")
def local_batch(cases_dir, env, tmp_path_factory):
    out = tmp_path_factory.mktemp("local")
    r = cli("batch", cases_dir, "--workers", 2, "--out", out, env=env)
    return r, out


def test_batch_local_pool(local_batch, cases_dir):
    r, out = local_batch
    assert r.returncode == 1, r.stdout + r.stderr
    assert "Traceback" not in r.stderr
    rows = read_summary(out / "summary.csv")
    assert [Path(row["file"]).name for row in rows] == ["a-paper.yaml", "b-copy.yaml", "c-broken.yaml"]
    assert [row["case"] for row in rows] == ["tunnel-paper", "paper-copy", "c-broken"]
    good, broken = rows[:2], rows[2]
    for row in good:
        assert row["status"] == "converged", row
        assert estimate(row, "E") == pytest.approx(10000, rel=0.01)
        assert estimate(row, "K0") == pytest.approx(1.0, rel=0.05)
        assert float(row["reduced_chi2"]) >= 0 and float(row["seconds"]) > 0
        assert row["message"] == ""
        assert float(row["std E[clay]"]) == pytest.approx(213, rel=0.05) and row["unit E[clay]"] == "kPa"
        assert (out / row["case"] / "summary.json").is_file()
        assert (out / row["case"] / "parameters.csv").is_file()
    assert broken["status"] == "error"
    assert "ground" in broken["message"] and "\n" not in broken["message"]
    assert broken["reduced_chi2"] == "" and estimate_missing(broken)
    assert "c-broken.yaml" in r.stderr
    header = next(csv.reader(open(out / "summary.csv")))
    assert header[:3] == ["case", "file", "status"] and header[-3:] == ["reduced_chi2", "seconds", "message"]


def estimate_missing(row: dict) -> bool:
    fixed = {"case", "file", "status", "reduced_chi2", "seconds", "message", "warnings"}
    return all(v == "" for k, v in row.items() if k not in fixed)


def _without_seconds(path: Path) -> list[dict]:
    rows = read_summary(path)
    for row in rows:
        row.pop("seconds")
    return rows


def test_batch_dask_gives_the_same_summary(local_batch, cases_dir, env, tmp_path, monkeypatch):
    distributed = pytest.importorskip("dask.distributed")
    monkeypatch.setenv("GEOBACK_CACHE", env["GEOBACK_CACHE"])  # inherited by the Dask workers
    out = tmp_path / "dask"
    with distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1,
                                  dashboard_address=None) as cluster:
        r = cli("batch", cases_dir, "--scheduler", cluster.scheduler_address, "--out", out, env=env)
    assert r.returncode == 1, r.stdout + r.stderr
    assert _without_seconds(out / "summary.csv") == _without_seconds(local_batch[1] / "summary.csv")
    assert (out / "paper-copy" / "summary.json").is_file()


@pytest.mark.slow
def test_batch_shipped_cases(env, tmp_path):
    """Every case shipped in cases/ and its subfolders (whatever is there) identifies without failure (slow:
    2.5 min for 24 cases on two cores; the top-level cases are each run in the default tier by
    test_examples, test_openings_cli, test_staged_outputs and test_plastic_outputs)."""
    shipped = sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "cases").rglob("*")
                     if p.suffix in (".yaml", ".yml") and not any(part.startswith(".") for part in p.relative_to(ROOT).parts))
    assert shipped, "no shipped cases"
    out = tmp_path / "out"
    r = cli("batch", "cases", "--workers", 2, "--out", out, env=env, cwd=ROOT)
    rows = read_summary(out / "summary.csv")
    assert sorted(Path(row["file"]).as_posix() for row in rows) == shipped
    failures = [f"{row['file']}: {row['status']}: {row['message']}" for row in rows if row["status"] != "converged"]
    assert not failures, "shipped cases that fail:\n" + "\n".join(failures)
    assert r.returncode == 0, r.stderr


# library ------------------------------------------------------------------------------------


def test_collect_cases(tmp_path):
    for sub in ("sub", ".hidden"):
        (tmp_path / sub).mkdir()
    for name in ("b.yaml", "a.yml", "sub/c.yaml", ".hidden/d.yaml", ".e.yaml", "readme.md"):
        (tmp_path / name).write_text("x")
    assert [p.name for p in collect_cases([tmp_path])] == ["a.yml", "b.yaml", "c.yaml"]  # recursive
    assert [p.name for p in collect_cases([str(tmp_path / "*.yaml")])] == ["b.yaml"]
    assert [p.name for p in collect_cases([str(tmp_path / "**" / "*.yaml")])] == ["b.yaml", "c.yaml"]
    assert [p.name for p in collect_cases([tmp_path / "b.yaml", tmp_path])] == ["a.yml", "b.yaml", "c.yaml"]
    with pytest.raises(GeobackError, match="no such file"):
        collect_cases([tmp_path / "missing"])
    with pytest.raises(GeobackError, match="no file matches"):
        collect_cases([str(tmp_path / "*.json")])
    (tmp_path / "empty").mkdir()
    with pytest.raises(GeobackError, match="holds no case files"):
        collect_cases([tmp_path / "empty"])


def test_output_folders_are_unique():
    paths = [Path("x/one.yaml"), Path("y/one.yaml"), Path("two.yaml"), Path("z/three.yaml")]
    assert output_folders(paths, ["tunnel", "tunnel", "tunnel", "other"]) == [
        "tunnel-one", "tunnel-one-2", "tunnel-two", "other"]


def test_summary_columns_are_the_union_of_parameters():
    rows = [{"case": "a", "file": "a.yaml", "status": "converged", "parameters": {"E": 1.0, "K0": 0.5},
             "reduced_chi2": 1.0, "seconds": 1.0, "message": ""},
            {"case": "b", "file": "b.yaml", "status": "converged", "parameters": {"E": 2.0, "nu[clay]": 0.3},
             "reduced_chi2": 2.0, "seconds": 1.0, "message": ""}]
    header, table = summary_table(rows)
    # issue 18: each parameter with its std and unit, and the warning codes (the rows above, as an
    # older writer left them, have neither: those cells stay empty)
    assert header == ["case", "file", "status", "E", "std E", "unit E", "K0", "std K0", "unit K0",
                      "nu[clay]", "std nu[clay]", "unit nu[clay]", "warnings", "reduced_chi2", "seconds", "message"]
    assert [table[1][header.index(n)] for n in ("E", "K0", "nu[clay]")] == [2.0, "", 0.3]
    rows[0].update(std={"E": 0.1, "K0": 0.01}, units={"E": "kPa", "K0": "-"}, warnings=["at-bound", "not-determined"])
    header, table = summary_table(rows)
    assert table[0][3:9] == [1.0, 0.1, "kPa", 0.5, 0.01, "-"]
    assert table[0][header.index("warnings")] == "at-bound not-determined"


def test_run_batch_in_process_same_case_names(tmp_path, cache, monkeypatch):
    """Two files with the same case name get separate folders; workers=1 runs in this process."""
    monkeypatch.setenv("GEOBACK_CACHE", str(cache))
    data = yaml.safe_load(PAPER.read_text())
    data["fit"] = {**data.get("fit", {}), "max_iterations": 1}
    (tmp_path / "first.yaml").write_text(yaml.safe_dump(data))
    (tmp_path / "second.yaml").write_text(yaml.safe_dump(data))
    before = {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    rows = run_batch(tmp_path, tmp_path / "out", workers=1)
    assert {k: os.environ.get(k) for k in before} == before  # the caller's environment is untouched
    assert [r["status"] for r in rows] == ["not converged", "not converged"]
    assert all("maximum number of iterations" in r["message"] for r in rows)
    name = data["name"]
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(
        ["summary.csv", f"{name}-first", f"{name}-second"])
    with pytest.raises(GeobackError, match="at least 1"):
        run_batch(tmp_path, tmp_path / "out", workers=0)


def test_batch_cli_user_errors(tmp_path, env):
    r = cli("batch", tmp_path / "missing", "--out", tmp_path / "out", env=env)
    assert r.returncode == 2 and r.stderr.startswith("error:") and len(r.stderr.strip().splitlines()) == 1
