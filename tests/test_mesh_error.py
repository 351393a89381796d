"""Discretisation error of the readings (geoback.inference.mesh_error): one run at the estimate on a mesh twice
as fine, compared with each reading's sigma; a warning above 0.3 sigma, or the error added to C_x."""
import copy

import numpy as np
import pytest
import yaml

from conftest import CASES
from geoback.case.loading import LoadedCase, case_from_data, load_case
from geoback.inference.identification import identify, prepare
from geoback.case.meshsize import refined_case

PAPER = yaml.safe_load((CASES / "tunnel-paper.yaml").read_text())


def coarse(tmp_path, mode="check"):
    data = copy.deepcopy(PAPER)
    data["mesh"] = {"size_tunnel": 1.5, "size_far": 10.0}  # far too coarse for these readings
    data["fit"]["mesh_error"] = mode
    path = tmp_path / f"coarse-{mode}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return load_case(path)


def test_paper_mesh_is_fine_enough():
    res = identify(load_case(CASES / "tunnel-paper.yaml"), mesh_error="check")
    me = res.mesh_error
    assert not me.skipped and me.fine_dofs > 2 * me.dofs
    assert me.max_sigma < 0.3
    assert "mesh-error" not in {c.code for c in res.caveats}


def test_difference_is_the_finer_mesh_minus_the_case_mesh(tmp_path):
    loaded = coarse(tmp_path)
    analysis = prepare(loaded)
    res = identify(analysis, mesh_error="check")
    me = res.mesh_error
    fine = prepare(loaded.with_case(refined_case(loaded.case, 2.0)))
    x_fine = fine.predict(res.fit.p).x
    np.testing.assert_allclose(me.difference, x_fine - analysis.predict(res.fit.p).x, rtol=1e-9, atol=1e-15)
    sigma = np.sqrt(np.diag(analysis.misfit.data.covariance))
    np.testing.assert_allclose(me.in_sigma, np.abs(me.difference) / sigma, rtol=1e-12)


def test_coarse_mesh_is_flagged_and_including_the_error_widens_the_intervals(tmp_path):
    checked = identify(coarse(tmp_path), mesh_error=None)
    assert checked.mesh_error.max_sigma > 0.3
    warn = [c for c in checked.caveats if c.code == "mesh-error"]
    assert warn and "mesh_error: include" in warn[0].message
    included = identify(coarse(tmp_path, "include"), mesh_error=None)
    assert included.mesh_error_included
    assert "mesh-error" not in {c.code for c in included.caveats}
    assert np.all(included.reliability.std > checked.reliability.std)
    assert included.reliability.chi2 < checked.reliability.chi2


def test_too_large_a_check_is_skipped_and_said(tmp_path, monkeypatch):
    import geoback.inference.mesh_error as me

    monkeypatch.setattr(me, "MAX_FINE_DOFS", 1000)
    res = identify(load_case(CASES / "tunnel-paper.yaml"), mesh_error="check")
    assert res.mesh_error.skipped and "DOFs" in res.mesh_error.text()
