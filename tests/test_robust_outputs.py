"""Nothing lost when a command fails or is killed: result sets replaced as a whole, --out checked
before any work, Ctrl-C messages that are true.

A results folder is *consistent* for a set kind ("run", ...) when its manifest
``.geoback-<kind>.json`` exists, every file it lists is present with the recorded SHA-256 (one
run id ties them), the visible files are exactly those of one complete set (plus files of other
sets and of the user), and the files agree with each other: parameters.csv, summary.json,
report.md and iterations.csv give the same estimates, and summary.json the case's hash.
"""
from __future__ import annotations

import csv
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

import geoback.reports.resultsets as outputs
from geoback.outputs import write_atomic
from geoback.case.loading import load_case
from geoback.reports.resultsets import ResultFolderError, check_result_set, result_set
from measure import run_cli

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "cases" / "tunnel-paper.yaml"


# ---------------------------------------------------------------------------- --out before any work
@pytest.fixture()
def env(tmp_path):
    e = dict(os.environ, GEOBACK_CACHE=str(tmp_path / "cache"))
    e.pop("GEOBACK_DEBUG", None)
    return e


def _bad_outs(tmp_path: Path) -> dict[str, tuple[str, str]]:
    (tmp_path / "a-file.txt").write_text("x")
    holder = tmp_path / "holder"
    (holder / "sub").mkdir(parents=True)
    return {"empty": ("", "found an empty string"),
            "blank": ("  ", "found an empty string"),
            "existing file": (str(tmp_path / "a-file.txt"), "found an existing file"),
            "file in the way": (str(tmp_path / "a-file.txt" / "out"), "found the file"),
            "current folder": (".", "found the current folder"),
            "parent of current folder": ("..", "found the current folder (or one holding it)"),
            "holds a subfolder": (str(holder), "found the subfolder 'sub'")}


COMMANDS = [["run", "-q"], ["simulate"], ["diagnose", "-q"], ["mesh"]]


@pytest.mark.parametrize("command", COMMANDS, ids=[c[0] for c in COMMANDS])
def test_bad_out_refused_before_any_work(command, tmp_path, env):
    work = tmp_path / "work"
    work.mkdir()
    for label, (value, words) in _bad_outs(tmp_path).items():
        proc = run_cli([command[0], PAPER, "--out", value] + command[1:], tmp_path, env=env, cwd=work)
        assert proc.returncode == 2, f"{label}: exit {proc.returncode}\n{proc.stderr}"
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: --out") and words in lines[0], f"{label}: {proc.stderr}"
        assert "Traceback" not in proc.stderr
        assert not (tmp_path / "cache").exists(), f"{label}: meshed before refusing"
    assert sorted(p.name for p in work.iterdir()) == []


def test_unwritable_out_refused(tmp_path, env):
    """A folder without write permission (or, for root, a file system that takes no folders)."""
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    places = [locked / "out"]
    if Path("/proc").is_dir():
        places.append(Path("/proc") / "geoback-out")
    try:
        for k, place in enumerate(places):
            cache = tmp_path / f"cache{k}"
            proc = run_cli(["run", PAPER, "-q", "--out", place], tmp_path, env=dict(env, GEOBACK_CACHE=str(cache)))
            if place.parent == locked and getattr(os, "geteuid", lambda: 1)() == 0:
                continue  # root may write anywhere
            assert proc.returncode == 2 and "not writable" in proc.stderr, proc.stderr
            assert not cache.exists()
    finally:
        locked.chmod(0o755)


def test_other_places_checked_before_any_work(tmp_path, env):
    (tmp_path / "a-file.txt").write_text("x")
    for args, words in ((["simulate", PAPER, "--readings-out", ""], "--readings-out: expected a file name"),
                        (["simulate", PAPER, "--readings-out", tmp_path], "found an existing folder"),
                        (["batch", PAPER, "--out", tmp_path / "a-file.txt"], "found an existing file"),
                        (["batch", PAPER, "--out", ""], "found an empty string")):
        proc = run_cli(args, tmp_path, env=env)
        assert proc.returncode == 2 and words in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
        assert not (tmp_path / "cache").exists()
    case = tmp_path / "case.yaml"  # the case's own output.dir is checked too
    data = yaml.safe_load(PAPER.read_text())
    data["output"] = {"dir": "a-file.txt"}
    case.write_text(yaml.safe_dump(data))
    proc = run_cli(["run", case], tmp_path, env=env)
    assert proc.returncode == 2 and "output.dir of the case" in proc.stderr and "existing file" in proc.stderr, \
        proc.stderr
    assert not (tmp_path / "cache").exists()


# ---------------------------------------------------------------------------- result_set itself
def _write(folder: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        write_atomic(folder / name, text)


def _visible(folder: Path) -> dict[str, str]:
    return {p.name: p.read_text() for p in sorted(folder.iterdir()) if not p.name.startswith(".")}


def _siblings(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.parent.iterdir() if p.name.startswith(f".{folder.name}.geoback-"))


def test_result_set_replaces_its_kind_and_keeps_the_rest(tmp_path):
    out = tmp_path / "results"
    with result_set(out, "run", run_id="first") as staging:
        _write(staging, {"parameters.csv": "old\n", "report.md": "old\n", "old-only.png": "old\n"})
    with result_set(out, "simulate") as staging:
        _write(staging, {"predicted.csv": "sim\n", "field.vtu": "sim\n"})
    (out / "notes.txt").write_text("mine\n")
    assert check_result_set(out, "run") == [] and check_result_set(out, "simulate") == []
    with result_set(out, "run", run_id="second") as staging:
        assert staging.parent == out.parent and staging.name.startswith(".results.geoback-")
        _write(staging, {"parameters.csv": "new\n", "report.md": "new\n", "field.vtu": "run\n"})
    assert _visible(out) == {"field.vtu": "run\n", "notes.txt": "mine\n", "parameters.csv": "new\n",
                             "predicted.csv": "sim\n", "report.md": "new\n"}  # old-only.png dropped
    run = json.loads((out / ".geoback-run.json").read_text())
    assert run["run_id"] == "second" and sorted(run["files"]) == ["field.vtu", "parameters.csv", "report.md"]
    sim = json.loads((out / ".geoback-simulate.json").read_text())
    assert sorted(sim["files"]) == ["predicted.csv"] and sim["replaced"] == {"field.vtu": "run"}
    assert check_result_set(out, "run") == [] and check_result_set(out, "simulate") == []
    assert _siblings(out) == []
    (out / "report.md").write_text("tampered\n")
    assert check_result_set(out, "run") == ["report.md: not the file of run second"]


def test_result_set_exception_leaves_the_folder_untouched(tmp_path):
    out = tmp_path / "results"
    with result_set(out, "run") as staging:
        _write(staging, {"a.csv": "old\n", "b.md": "old\n"})
    before = _visible(out)
    inode = out.stat().st_ino
    for exc in (RuntimeError("disk full"), KeyboardInterrupt()):
        with pytest.raises(type(exc)):
            with result_set(out, "run") as staging:
                _write(staging, {"a.csv": "new\n"})
                raise exc
        assert _visible(out) == before and out.stat().st_ino == inode
        assert _siblings(out) == []
    assert "still holds its previous results" in outputs.interrupted_note()


def test_linked_results_folder_keeps_its_link(tmp_path):
    target = tmp_path / "disk" / "results"
    target.mkdir(parents=True)
    link = tmp_path / "results"
    link.symlink_to(target)
    for k in range(2):
        with result_set(link, "run") as staging:
            _write(staging, {"a.csv": f"{k}\n"})
        assert link.is_symlink() and _visible(link) == {"a.csv": f"{k}\n"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["disk", "results"]
    assert _siblings(target) == []


def test_result_set_refuses_a_folder_with_subfolders(tmp_path):
    out = tmp_path / "results"
    (out / "keep").mkdir(parents=True)
    with pytest.raises(ResultFolderError, match="subfolder 'keep'"):
        with result_set(out, "run") as staging:
            _write(staging, {"a.csv": "x\n"})
    assert (out / "keep").is_dir() and _siblings(out) == []


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_leftovers_of_killed_writers_are_removed(tmp_path):
    out = tmp_path / "results"
    with result_set(out, "run") as staging:
        _write(staging, {"a.csv": "1\n"})
    dead = _dead_pid()
    stale_new = out.parent / f".results.geoback-{outputs._HOST}-{dead}-0badc0de.new"
    stale_old = out.parent / f".results.geoback-{outputs._HOST}-{dead}-0badc0df.old"
    stale_ready = out.parent / f".results.geoback-{outputs._HOST}-{dead}-0badc0e1.ready"
    live = out.parent / f".results.geoback-{outputs._HOST}-{os.getppid()}-0badc0e0.new"  # a writer still running
    for folder in (stale_new, stale_old, stale_ready, live):
        folder.mkdir()
        (folder / "half.csv").write_text("half")
    with result_set(out, "run") as staging:
        _write(staging, {"a.csv": "2\n"})
    assert not stale_new.exists() and not stale_old.exists() and not stale_ready.exists() and live.exists()
    assert _visible(out) == {"a.csv": "2\n"}


@pytest.mark.parametrize("left", ["new", "old", "both"])
def test_two_rename_fallback_and_its_recovery(tmp_path, monkeypatch, left):
    """Where the atomic exchange is unavailable the swap takes two renames; a process killed
    between them leaves no folder, and the next writer puts the right set back first."""
    monkeypatch.setattr(outputs, "_exchange", lambda a, b: False)
    out = tmp_path / "results"
    with result_set(out, "run", run_id="one") as staging:
        _write(staging, {"a.csv": "1\n"})
    with result_set(out, "run", run_id="two") as staging:
        _write(staging, {"a.csv": "2\n"})
    assert _visible(out) == {"a.csv": "2\n"} and _siblings(out) == []
    # simulate a kill between the renames: the folder retired, the complete staging not yet in place
    dead = _dead_pid()
    prefix = f".results.geoback-{outputs._HOST}-{dead}-deadbeef"
    retired, staged = out.parent / f"{prefix}.old", out.parent / f"{prefix}.ready"
    shutil.copytree(out, staged)
    (staged / "a.csv").write_text("3\n")
    manifest = json.loads((staged / ".geoback-run.json").read_text())
    manifest.update(run_id="three", files={"a.csv": outputs._sha256(staged / "a.csv")})
    (staged / ".geoback-run.json").write_text(json.dumps(manifest))
    os.rename(out, retired)
    if left == "new":
        shutil.rmtree(retired)
    elif left == "old":
        shutil.rmtree(staged)
    outputs._recover(out)
    expected = {"new": "3\n", "old": "2\n", "both": "3\n"}[left]
    assert _visible(out) == {"a.csv": expected} and check_result_set(out, "run") == []
    assert _siblings(out) == []


# ---------------------------------------------------------------------------- kill -9 and Ctrl-C
def _old_variant(tmp_path: Path) -> Path:
    """The paper case fitted differently (identity weighting, 2 iterations): every file differs."""
    data = yaml.safe_load(PAPER.read_text())
    weighting = data.get("fit", {}).get("weighting", "full")
    data["fit"] = {**data.get("fit", {}), "max_iterations": 2,
                   "weighting": "full" if weighting == "identity" else "identity"}
    path = tmp_path / "old.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _estimates_agree(folder: Path) -> None:
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["case_hash"] in (load_case(PAPER).digest(), load_case(folder.parent / "old.yaml").digest())
    est = {n: v["estimate"] for n, v in summary["parameters"].items()}
    with open(folder / "parameters.csv") as fh:
        table = {r["name"]: float(r["estimate"]) for r in csv.DictReader(fh)}
    assert table == est, (table, est)
    report = (folder / "report.md").read_text()
    for name, value in est.items():
        assert f"| {name} |" in report and f"{value:.6g}" in report, (name, value)
    with open(folder / "iterations.csv") as fh:
        rows = [r for r in csv.DictReader(fh) if r["accepted"] == "True"]
    if rows:
        assert all(abs(float(rows[-1][n]) - v) <= 1e-9 * max(1.0, abs(v)) for n, v in est.items())


def consistent(folder: Path, old: Path, old_names: list[str]) -> str:
    """'old' or 'new' when `folder` holds a complete, consistent run set; fails otherwise."""
    visible = sorted(p.name for p in folder.iterdir() if not p.name.startswith("."))
    assert visible == old_names, f"files {visible}"
    assert check_result_set(folder, "run") == [], check_result_set(folder, "run")
    run_id = json.loads((folder / ".geoback-run.json").read_text())["run_id"]
    old_id = json.loads((old / ".geoback-run.json").read_text())["run_id"]
    if run_id == old_id:
        for name in old_names:
            assert (folder / name).read_bytes() == (old / name).read_bytes(), f"{name} differs from the old set"
        return "old"
    _estimates_agree(folder)
    return "new"


@pytest.fixture(scope="module")
def previous_result(tmp_path_factory):
    """An older run with figures, and how long a run takes (warm mesh cache)."""
    tmp = tmp_path_factory.mktemp("kill")
    env = dict(os.environ, GEOBACK_CACHE=str(tmp / "cache"))
    env.pop("GEOBACK_DEBUG", None)
    old = tmp / "old"
    case = _old_variant(tmp)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "geoback.commands.cli", "run", str(case), "--plots", "-q", "--out", str(old)],
                          capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode in (0, 1), proc.stderr
    names = sorted(p.name for p in old.iterdir() if not p.name.startswith("."))
    assert {"parameters.csv", "report.md", "summary.json", "objective_contours.png", "field.vtu"} <= set(names)
    return tmp, env, old, names, time.perf_counter() - t0


def _interrupt(tmp: Path, env: dict, old: Path, k: int, after: float, sig: int):
    target = tmp / f"x{k}"
    if target.exists():
        shutil.rmtree(target)
    shutil.copytree(old, target)
    proc = subprocess.Popen([sys.executable, "-m", "geoback.commands.cli", "run", str(PAPER), "--plots", "-q",
                             "--out", str(target)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        proc.wait(timeout=after)
    except subprocess.TimeoutExpired:
        proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    return target, proc.returncode, err


def _kill_trials(previous_result, moments: list[float], sig=signal.SIGKILL) -> dict:
    tmp, env, old, names, seconds = previous_result
    outcomes = {"old": 0, "new": 0}
    for k, fraction in enumerate(moments):
        target, code, err = _interrupt(tmp, env, old, k, fraction * seconds * 1.2, sig)
        state = consistent(target, old, names)
        outcomes[state] += 1
        if sig == signal.SIGINT and code == 130:  # Ctrl-C: the message must say what is true
            assert "Traceback" not in err, err
            if state == "old":
                assert "still holds its previous results" in err, err
            else:
                assert "are complete" in err, err
    # the next run over a folder a killed run left behind succeeds, and clears what it left
    proc = subprocess.run([sys.executable, "-m", "geoback.commands.cli", "run", str(PAPER), "--plots", "-q", "--out",
                           str(target)], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert consistent(target, old, names) == "new"
    assert _siblings(target) == [], _siblings(target)
    return outcomes


@pytest.mark.slow  # 35 s; the set's replacement and the removal of killed writers' leftovers: default tier
def test_kill_9_during_run_leaves_a_consistent_set(previous_result):
    """Default suite: three kills, early (computing), late (writing) and at about the end."""
    outcomes = _kill_trials(previous_result, [0.3, 0.8, 0.97])
    assert sum(outcomes.values()) == 3


@pytest.mark.slow
def test_kill_9_at_random_moments_20_of_20(previous_result):
    rng = random.Random(20)
    outcomes = _kill_trials(previous_result, [rng.uniform(0.0, 1.0) for _ in range(20)])
    assert sum(outcomes.values()) == 20
    print(f"kill -9 at 20 random moments: {outcomes}")


@pytest.mark.slow
def test_ctrl_c_at_random_moments_says_what_is_true(previous_result):
    rng = random.Random(7)
    _kill_trials(previous_result, [rng.uniform(0.2, 1.0) for _ in range(6)], sig=signal.SIGINT)
