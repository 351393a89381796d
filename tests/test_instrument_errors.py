"""Inclinometer systematic errors as named quantities: bias shift bias[I] (a constant slope offset of
every reading, so an error bias * L_n growing from the reference end) and depth offset zoff[I] (the
probe read zoff deeper: the observation operator at the shifted points), with exact sensitivities."""
import numpy as np
import pytest

from conftest import CASES
from geoback.case.loading import Parameter, load_case
from geoback.errors import GeobackError
from geoback.inference.identification import prepare
from geoback.inference.synthetic import synthetic_readings

NULL = CASES / "concealed" / "null-1.yaml"


@pytest.fixture(scope="module")
def analysis():
    return prepare(load_case(NULL), parameters=[], with_readings=False)


def test_error_names_belong_to_inclinometers(analysis):
    survey = analysis.simulation.survey
    assert survey.error_names == ["bias[I1]", "zoff[I1]", "bias[I2]", "zoff[I2]"]
    assert survey.P.shape[0] == survey.m and survey.D.shape[0] == 2 * 19  # readings; each inclinometer's depth derivatives
    assert survey.operator({}).shape[0] == survey.m + 2 * 19  # what a physics reading depth offsets computes


def test_bias_shift_grows_linearly_from_the_reference_end(analysis):
    sim = analysis.simulation
    v = dict(analysis.values)
    x0 = sim.predict(v).x
    v["bias[I1]"] = 2e-4
    dx = sim.predict(v).x - x0
    rows = sim.survey.rows("I1")
    block = sim.survey.blocks[0]
    assert np.allclose(dx[rows], 2e-4 * np.cumsum(block.lengths))  # L_n from the toe
    dx[rows] = 0
    assert np.abs(dx).max() < 1e-15  # nothing else moves


def test_depth_offset_equals_the_instrument_moved_deeper(analysis):
    """zoff is exact: the same as the case with the inclinometer's toe (and stations) 0.3 m deeper."""
    loaded = load_case(NULL)
    case = loaded.case
    moved = [i.model_copy(update={"toe_depth": i.toe_depth + 0.3}) if i.name == "I1" else i for i in case.instruments]
    other = prepare(loaded.with_case(case.model_copy(update={"instruments": moved})), parameters=[],
                    with_readings=False)
    v = dict(analysis.values)
    shifted = analysis.simulation.predict({**v, "zoff[I1]": 0.3}).x
    assert np.allclose(shifted, other.simulation.predict(v).x, rtol=0, atol=1e-12)
    assert np.abs(shifted - analysis.simulation.predict(v).x).max() > 1e-3  # a visible effect (mm)


@pytest.mark.parametrize("name,h", [("bias[I1]", 1e-7), ("zoff[I1]", 1e-4), ("zoff[I2]", 1e-4), ("E[clay]", 1.0),
                                    ("K0", 1e-5)])
def test_sensitivities_are_exact(analysis, name, h):
    """Central differences of the readings with a bias shift and depth offsets switched on."""
    sim = analysis.simulation
    v = dict(analysis.values, **{"bias[I1]": 1e-4, "zoff[I1]": 0.2, "zoff[I2]": -0.1, "B[I1]": 0.001})
    names = ["E[clay]", "K0", "bias[I1]", "zoff[I1]", "zoff[I2]"]
    A = sim.predict(v, names, sensitivities=True).A
    j = names.index(name)
    up, down = dict(v), dict(v)
    up[name] += h
    down[name] -= h
    fd = (sim.predict(up).x - sim.predict(down).x) / (2 * h)
    assert np.linalg.norm(fd - A[:, j]) <= 1e-6 * np.linalg.norm(A[:, j])


def test_study_data_with_instrument_errors_and_units():
    loaded = load_case(NULL)
    clean = synthetic_readings(loaded, refine=1.0)
    err = synthetic_readings(loaded, refine=1.0, values={"bias[I2]": "0.2 mrad", "zoff[I1]": "100 mm"})
    L = np.cumsum(np.full(19, 1.5))
    assert np.allclose(err["I2"] - clean["I2"], 2e-4 * L)
    assert np.abs(err["I1"] - clean["I1"]).max() > 1e-4
    assert np.array_equal(err["S"], clean["S"])
    with pytest.raises(GeobackError, match="bias\\[I1\\], zoff\\[I1\\]"):
        synthetic_readings(loaded, refine=1.0, values={"bias[X1]": 1e-4})


def test_an_instrument_error_can_be_identified():
    """bias[I1] identified with E and K0 from readings that carry it."""
    from geoback.inference.identification import identify

    loaded = load_case(NULL)
    an = prepare(loaded, parameters=[Parameter(name="E", initial=8000.0), Parameter(name="K0", initial=0.8),
                                     Parameter(name="bias[I1]", initial=0.0, bounds=(-0.01, 0.01))],
                 with_readings=False)
    x = an.simulation.predict({**an.values, "bias[I1]": 3e-4}).x
    res = identify(an.with_readings(x))
    assert res["bias[I1]"].value == pytest.approx(3e-4, rel=1e-6)


def test_an_inclinometer_read_at_several_stages_has_one_bias_shift_and_no_depth_offset():
    """The staged physics observes with P alone: one bias shift per inclinometer over its surveys
    (the same probe), its column L_n on the rows of every stage; no depth offset to hypothesise."""
    staged = prepare(load_case(CASES / "staged-tunnel.yaml"), parameters=[], with_readings=False)
    survey = staged.simulation.survey
    assert survey.error_names == ["bias[I1]"] and not staged.simulation.reads_depth_offsets
    rows = [i for i, lab in enumerate(survey.labels) if lab.instrument == "I1"]
    col = survey.bias_column("bias[I1]")
    assert len({survey.labels[i].stage for i in rows}) == 2
    assert np.all(col[rows] != 0) and np.all(np.delete(col, rows) == 0)
    v = dict(staged.values)
    x0 = staged.simulation.predict(v).x
    assert np.allclose(staged.simulation.predict({**v, "bias[I1]": 1e-4}).x - x0, 1e-4 * col)
