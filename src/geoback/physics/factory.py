"""The simulation a case asks for: the factory above the implementations (the interface and its value
types are in ``simulation.py``, below them).

``IMPLEMENTATIONS`` is the registry of every ``Simulation``: which cases each one takes (the first
that takes a case is chosen) and a shipped case it is built from. The contract every simulation
passes (``tests/test_simulation_contract.py``) runs over this table, so a new physics is one new
module and one row here, and is checked with the others.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Callable

from geoback.case.strength import is_plastic
from geoback.physics.simulation import Simulation


@dataclass(frozen=True)
class Implementation:
    """A row of the registry: `name`, the class (`module`, `cls`: imported when chosen), `takes` (does
    it simulate this case?) and `example` (a shipped case it is built from, relative to the
    repository: the contract test's)."""

    name: str
    module: str
    cls: str
    takes: Callable[[object], bool]
    example: str

    def load(self) -> type[Simulation]:
        return getattr(importlib.import_module(self.module), self.cls)


def _has_openings(case) -> bool:
    return hasattr(case.geometry, "openings")


def _yielding_openings(case) -> bool:
    return _has_openings(case) and is_plastic(case)


IMPLEMENTATIONS: tuple[Implementation, ...] = (
    Implementation("yielding-excavation", "geoback.physics.excavation_plastic", "YieldingExcavationSimulation",
                   _yielding_openings, "cases/plastic-heading-bench.yaml"),  # openings in mohr-coulomb ground
    Implementation("excavation", "geoback.physics.excavation", "ExcavationSimulation", _has_openings,
                   "cases/natm-heading-bench.yaml"),  # openings of any shape, element removal, stages
    Implementation("plastic", "geoback.physics.plastic", "PlasticSimulation", is_plastic,
                   "cases/plastic-tunnel.yaml"),  # a mohr-coulomb layer (stages included)
    Implementation("staged", "geoback.physics.staged", "StagedSimulation",
                   lambda case: case.construction is not None, "cases/staged-tunnel.yaml"),  # stages, a lining
    Implementation("elastic", "geoback.physics.elastic", "ElasticSimulation", lambda case: True,
                   "cases/tunnel-paper.yaml"),  # the one-step linear-elastic excavation
)


def implementation(case) -> Implementation:
    """The registry's row that simulates `case` (the first that takes it)."""
    return next(i for i in IMPLEMENTATIONS if i.takes(case))


def make_simulation(loaded, mesh=None, backend: str | None = None, blocks=None, extensions=None) -> Simulation:
    """The simulation a case asks for (``IMPLEMENTATIONS``), with the extension table of `geoback
    diagnose` available (``physics/extensions.py``) unless another table is given: the one-step
    linear-elastic excavation, the staged one (``staged.py``) when the case has a construction
    section, or the elastoplastic one (``plastic.py``, stages included) when a layer is mohr-coulomb;
    for a section with openings, element removal (``excavation.py``), in yielding ground when a layer is
    mohr-coulomb (``excavation_plastic.py``)."""
    from geoback.physics.extensions import EXTENSIONS

    cls = implementation(loaded.case).load()
    return cls(loaded, mesh=mesh, blocks=blocks, backend=backend,
               extensions=EXTENSIONS if extensions is None else extensions)
