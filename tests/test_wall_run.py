"""The shipped propped excavation end to end through `geoback run --plots` (slow): walls.csv, supports.csv,
the wall, support and forecast figures, and the forecast of the level-2 props' force equal to supports.csv."""
from __future__ import annotations

import csv
import subprocess
import sys

import pytest

pytestmark = pytest.mark.slow


def test_the_propped_case_run_writes_walls_supports_and_their_figures(tmp_path):
    from conftest import CASES

    out = subprocess.run([sys.executable, "-m", "geoback.commands.cli", "run", str(CASES / "propped-excavation.yaml"),
                          "--plots", "--out", str(tmp_path), "-q"], capture_output=True, text=True, timeout=900)
    assert out.returncode in (0, 3), out.stderr
    for f in ("walls.csv", "supports.csv", "walls.png", "supports.png", "forecast_prop-force-level-2.png",
              "forecast_wall-moment.png", "mesh.png", "instruments.png", "measured_vs_predicted.png"):
        assert (tmp_path / f).stat().st_size > (10_000 if f.endswith(".png") else 300), f
    assert len(list(csv.DictReader(open(tmp_path / "supports.csv")))) == 6  # P1 from level1, P2 from level2
    report = (tmp_path / "report.md").read_text()
    assert "## Walls and supports" in report and "kN per prop" in report
    fc = [r for r in csv.DictReader(open(tmp_path / "forecast.csv")) if r["forecast"] == "prop-force-level-2"]
    sup = [r for r in csv.DictReader(open(tmp_path / "supports.csv")) if r["support"] == "P2" and r["stage"] == "lift3"]
    assert fc[0]["unit"] == "kN" and float(fc[0]["value"]) == pytest.approx(float(sup[0]["force per support [kN]"]))
    assert float(fc[0]["std"]) == pytest.approx(float(sup[0]["force per support_std [kN]"]), rel=1e-6)
    assert "axial force" in report and "thrust" not in report.split("## Forecasts")[1]
    assert "from the tunnel axis" not in report
    import json

    summary = json.loads((tmp_path / "summary.json").read_text())
    p2 = summary["walls"]["supports"]["P2"]["stages"]["lift3"]
    assert p2["force_per_support_kN"] == pytest.approx(float(sup[0]["force per support [kN]"]))
