"""The simulation a case asks for: the factory above the implementations (the interface and its value
types are in ``simulation.py``, below them)."""
from __future__ import annotations

from geoback.case.strength import is_plastic
from geoback.physics.simulation import Simulation


def make_simulation(loaded, mesh=None, backend: str | None = None, blocks=None, extensions=None) -> Simulation:
    """The simulation a case asks for, with the extension table of `geoback diagnose` available
    (``physics/extensions.py``) unless another table is given: the one-step linear-elastic
    excavation, the staged one (``staged.py``) when the case has a construction section, or the
    elastoplastic one (``plastic.py``, stages included) when a layer is mohr-coulomb."""
    from geoback.physics.elastic import ElasticSimulation
    from geoback.physics.extensions import EXTENSIONS

    if is_plastic(loaded.case):
        from geoback.physics.plastic import PlasticSimulation

        return PlasticSimulation(loaded, mesh=mesh, blocks=blocks, backend=backend,
                                 extensions=EXTENSIONS if extensions is None else extensions)
    if loaded.case.construction is not None:
        from geoback.physics.staged import StagedSimulation

        return StagedSimulation(loaded, mesh=mesh, blocks=blocks, backend=backend,
                                extensions=EXTENSIONS if extensions is None else extensions)
    return ElasticSimulation(loaded, mesh=mesh, blocks=blocks, backend=backend,
                             extensions=EXTENSIONS if extensions is None else extensions)
