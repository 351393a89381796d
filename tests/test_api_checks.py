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
