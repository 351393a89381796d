"""`geoback diagnose` on shipped concealed-physics cases (readings from a finer mesh with noise)."""
import json
import subprocess
import sys

import pytest

from conftest import CASES
from geoback.case import load_case
from geoback.diagnose import diagnose

CONCEALED = CASES / "concealed"


def test_stiffness_gradient_is_found_and_estimated():
    d = diagnose(load_case(CONCEALED / "stiffness-gradient.yaml"))
    assert not d.adequate_before
    assert [s.hypothesis.kind for s in d.accepted] == ["stiffness-gradient"]
    rel = d.final_reliability
    lo, hi = rel.interval95()
    i = rel.names.index("Egrad[clay]")
    assert lo[i] <= 400.0 <= hi[i]  # the concealed truth
    assert d.adequate_after
    assert d.final_reliability.reduced_chi2 < d.baseline_reliability.reduced_chi2 / 5
    ranking = d.rounds[0].ranking
    beta = next(s for s in ranking if s.hypothesis.kind == "stress-release")
    assert beta.collinear_with is not None and "E[clay]" in beta.collinear_with


def test_null_case_says_nothing_is_missing(tmp_path):
    out = subprocess.run([sys.executable, "-m", "geoback.cli", "diagnose", str(CONCEALED / "null-1.yaml"),
                          "--out", str(tmp_path), "-q"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "Nothing is missing" in out.stdout
    data = json.loads((tmp_path / "diagnosis.json").read_text())
    assert data["adequate_before"] is True and data["missing"] == []
    assert (tmp_path / "diagnosis.png").stat().st_size > 0
