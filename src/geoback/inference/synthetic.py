"""Synthetic readings beside the simulation (SimPEG's ``make_synthetic_data``): what every instrument
would read on a finer mesh (no inverse crime), optionally with noise drawn from its C_x (eqn 10)."""
from __future__ import annotations

from typing import Mapping

import numpy as np

from geoback.case.loading import LoadedCase
from geoback.case.meshsize import refined_case
from geoback.inference.identification import prepare
from geoback.inference.misfit import block_noise
from geoback.inference.parameters import resolve_values


def synthetic_readings(loaded: LoadedCase, refine: float = 2.0, values: Mapping | None = None,
                       noise_seed: int | None = None, noise_scale: float = 1.0, by_stage: bool = False) -> dict:
    """Readings of every instrument from a finer mesh, optionally with noise drawn from C_x.

    `values` overrides named quantities, by name as in a case file, with units if wished (e.g.
    {'Egrad[clay]': 500, 'E': '12 MPa', 'B[I1]': 0.002}); unknown names are refused. An
    inclinometer's bias shift ('bias[I1]': 2e-4 rad) adds bias * L_n to its readings; its depth
    offset ('zoff[I1]': '300 mm') reads its stations and reference end that much deeper (the
    observation operator at the shifted points). Noise is L z with C_x = L L^t per instrument
    (eqn 10; ``misfit.block_noise``, as ``Data.noise`` draws it), seeded, independent from stage
    to stage. Returns {instrument: readings} at the last construction stage, or with `by_stage`
    {instrument: {stage: readings}} at every stage."""
    fine = loaded.with_case(refined_case(loaded.case, refine))
    analysis = prepare(fine, parameters=[], with_readings=False)
    sim = analysis.simulation
    named = dict(analysis.values)
    named.update(resolve_values(sim, values or {}))
    x = sim.predict(named).x  # a reference end that moved: readings = P u - G c (eqns 11, 15, 18)
    rng = np.random.default_rng(noise_seed) if noise_seed is not None else None
    out, offset = {}, 0
    for block in sim.survey.blocks:
        xi = x[offset:offset + block.m].copy()
        if rng is not None:
            xi += noise_scale * block_noise(block, rng)
        out.setdefault(block.name, {})[block.stage] = xi
        offset += block.m
    if by_stage:
        return out
    last = sim.stages[-1]
    return {name: sets[last] for name, sets in out.items()}
