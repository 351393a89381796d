"""The examples in docs/examples/ run as they are (scikit-fem style: documentation that is tested)."""
import runpy
import sys
from pathlib import Path

import pytest

EXAMPLES = sorted((Path(__file__).resolve().parents[1] / "docs" / "examples").glob("*.py"))


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_runs(path, capsys, monkeypatch):
    monkeypatch.setattr(sys, "argv", [str(path), "50"])
    runpy.run_path(str(path), run_name="__main__")
    out = capsys.readouterr().out
    assert out.strip(), "an example prints what it shows"
    if path.stem == "identify_paper_case":
        assert "E[clay]" in out and "factorisations for the whole fit: 1" in out
    if path.stem == "monte_carlo":
        assert "50 replicates" in out and "1 factorisation(s)" in out


def test_examples_exist():
    assert {p.stem for p in EXAMPLES} >= {"identify_paper_case", "monte_carlo"}
