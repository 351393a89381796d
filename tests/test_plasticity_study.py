"""The mesh-convergence study of the elastoplastic deep tunnel runs (small version) and meets 2 %."""
from __future__ import annotations

import sys
from pathlib import Path

STUDIES = Path(__file__).resolve().parents[1] / "studies"
if str(STUDIES) not in sys.path:
    sys.path.insert(0, str(STUDIES))


def test_plastic_convergence_small(tmp_path, capsys):
    import plastic_convergence as study

    rows = study.main(["--small", "--out", str(tmp_path)])
    assert (tmp_path / "plastic_convergence.csv").stat().st_size > 0
    assert "R_p err" in capsys.readouterr().out
    assert len(rows) == 3 * 2 * 2 and all(r["status"] == "ok" for r in rows)
    for r in rows:
        assert abs(r["Rp_err"]) < 0.02 and abs(r["uR_err"]) < 0.02, r
        assert r["max_residual"] <= 1e-10
    # the error falls with the mesh size (full release)
    for psi in (0.0, 10.0, 30.0):
        coarse, fine = [r for r in rows if r["psi"] == psi and r["lam"] == 1.0]
        assert abs(fine["uR_err"]) < abs(coarse["uR_err"]) and abs(fine["Rp_err"]) < abs(coarse["Rp_err"])
