"""Exact sensitivities of the diagnose extensions (eqns 34-40 through the complex-step ground map)
against central finite differences, and the eqn 37b derivative of D against the ERRATA form."""
import numpy as np
import pytest
import yaml

from conftest import CASES, central_difference_error
from geoback.case.loading import LoadedCase, case_from_data
from geoback.physics.ground import plane_strain_cross_anisotropic, plane_strain_isotropic
from geoback.inference.identification import prepare

pytestmark = pytest.mark.quick  # the edit-test loop tier (`pytest -m quick`)


@pytest.fixture(scope="module")
def problem():
    data = yaml.safe_load((CASES / "concealed" / "stiffness-gradient.yaml").read_text())
    for ins in data["instruments"]:
        ins.pop("readings_file")
    data["parameters"] = [
        {"name": "E", "initial": 9000.0}, {"name": "K0", "initial": 0.8}, {"name": "nu", "initial": 0.3},
        {"name": "Egrad[clay]", "initial": 150.0}, {"name": "n[clay]", "initial": 1.3},
        {"name": "m[clay]", "initial": 0.9}, {"name": "K0grad", "initial": 0.02}, {"name": "beta", "initial": 0.8},
        {"name": "Esplit[clay]", "initial": 15000.0}]
    loaded = LoadedCase(case_from_data(data), CASES / "concealed" / "x.yaml", {})
    return prepare(loaded, with_readings=False, values={"zsplit[clay]": 18.0})


def test_extension_sensitivities_match_central_differences(problem):
    p = problem.parameters.initial.copy()
    A = problem.predict(p, sensitivities=True).A
    for j, name in enumerate(problem.parameters.names):
        err = central_difference_error(problem, p, A, j, 1e-5 * max(abs(p[j]), 1e-2))
        assert err < 1e-6, (name, err)


def test_dD_dnu_is_the_corrected_eqn_37b():
    E, nu = 7000.0, 0.37
    h = 1e-30
    d = np.array(plane_strain_isotropic(E, nu + 1j * h)).imag / h  # (D11, D22, D12, D33)
    f = E / ((1 + nu) ** 2 * (1 - 2 * nu) ** 2)  # ERRATA: (1 + nu)^2, not (1 + nu^2)
    assert np.allclose(d, [f * 2 * nu * (2 - nu), f * 2 * nu * (2 - nu), f * (1 + 2 * nu ** 2),
                           -f * (1 - 2 * nu) ** 2 / 2], rtol=1e-12)
    printed = E / ((1 + nu ** 2) * (1 - 2 * nu) ** 2)
    assert not np.isclose(d[0], printed * 2 * nu * (2 - nu), rtol=1e-3)


def test_cross_anisotropy_reduces_to_isotropy():
    assert np.allclose(plane_strain_cross_anisotropic(8000.0, 0.3, 1.0, 1.0, 0.3), plane_strain_isotropic(8000.0, 0.3),
                       rtol=1e-14)
