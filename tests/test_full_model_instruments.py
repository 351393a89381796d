"""Instruments anywhere in a full model (issue 19): an inclinometer on the other side of the centre line
(x < 0) is accepted and reads the mirror image of its twin at x > 0 around a centred tunnel; the
circular tunnel's half-model refuses it, located."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from geoback.case.loading import LoadedCase, case_from_data
from geoback.errors import CaseError
from geoback.inference.identification import prepare


def inclinometer(name: str, x: float) -> dict:
    return {"name": name, "kind": "inclinometer", "x": x, "toe_depth": 28.0, "spacing": 2.0, "stations": 12,
            "sigma": 2e-4}


def test_an_inclinometer_at_negative_x_reads_the_mirror_image():
    data = {"name": "centred", "geometry": {"model": "full", "width": 100.0, "depth": 30.0, "openings": [
        {"name": "tunnel", "shape": "circle", "centre": [0.0, -15.0], "radius": 3.0}]},
        "ground": {"unit_weight": 20.0, "K0": 0.7, "layers": [{"name": "clay", "top": 0.0, "E": 40000.0, "nu": 0.3}]},
        "mesh": {"size_tunnel": 0.4, "size_far": 4.0},
        "instruments": [inclinometer("west", -6.0), inclinometer("east", 6.0)]}
    loaded = LoadedCase(case_from_data(data, {}, file="centred.yaml"), Path("centred.yaml"), {})
    sim = prepare(loaded, parameters=[], with_readings=False).simulation
    x = sim.predict(sim.quantities()).x
    west, east = x[:12], x[12:]
    assert np.abs(east).max() > 1e-3  # millimetres towards the tunnel
    assert np.all(east < 0) and np.all(west > 0)  # u_x along +x: both move towards the tunnel at x = 0
    assert np.abs(west + east).max() <= 0.02 * np.abs(east).max()  # mirror images (to the mesh's asymmetry)


def test_the_circular_half_model_refuses_negative_x_located():
    data = {"name": "paper", "geometry": {"radius": 3.0, "axis_depth": 15.0, "width": 40.0, "depth": 30.0},
            "ground": {"unit_weight": 20.0, "K0": 0.7, "layers": [{"name": "clay", "top": 0.0, "E": 40000.0, "nu": 0.3}]},
            "instruments": [inclinometer("I1", -6.0)]}
    with pytest.raises(CaseError) as err:
        case_from_data(data, {}, file="paper.yaml")
    assert err.value.field == "instruments[0].x"
    assert "expected the borehole inside the ground (x between 0 and 40" in err.value.reason and "found x -6" in err.value.reason
