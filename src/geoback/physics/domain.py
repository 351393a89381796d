"""What every simulation of a case stands on, built in one place: the mesh, the FE model, the ground
as a function of the named values, the construction plan (its stages), the survey read, the counters
and the set-up timings.

``build_domain`` makes it (meshing unless a mesh is given); the simulations hold it and add their
physics (``elastic.py``, ``staged.py``, ``plastic.py``). A domain is a value: another survey is
``domain.reading(blocks)``, a new domain sharing everything else (the counters included), which is
how ``Simulation.surveying`` gives a view on other instruments.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Mapping

import numpy as np

from geoback.case.construction import StagePlan
from geoback.observation.instruments import Survey, build_survey
from geoback.physics.fem import FEModel
from geoback.physics.ground import Ground
from geoback.physics.mesh import Mesh, build_mesh
from geoback.physics.simulation import Counters, refuse_late_blocks, stage_survey


@dataclass(frozen=True, eq=False)
class Domain:
    """A case meshed and assembled with its survey (module docstring)."""

    loaded: object  # the LoadedCase
    mesh: Mesh
    fe: FEModel
    ground: Ground
    plan: StagePlan
    survey: Survey
    counters: Counters
    timings: dict
    backend: str | None = None

    @property
    def stages(self) -> list[str]:
        return list(self.plan.names)

    @cached_property
    def row_stage(self) -> np.ndarray:
        """The construction stage (index) of every survey row."""
        index = {n: k for k, n in enumerate(self.plan.names)}
        return np.array([index[lab.stage] for lab in self.survey.labels], np.int64)

    def reading(self, blocks) -> "Domain":
        """The same domain reading the instruments `blocks` (forecast points, candidate instruments)."""
        return self.with_survey(build_survey(blocks, self.fe))

    def with_survey(self, survey: Survey) -> "Domain":
        return replace(self, survey=survey)

    def elastic_stress(self, values: Mapping, u_full: np.ndarray) -> np.ndarray:
        """Total stress (sxx, syy, sxy) per element of linear-elastic ground displaced by `u_full`
        (all dofs): the initial geostatic stress plus the excavation's increment."""
        st = self.ground.state(values)
        eps = self.fe.element_strain(u_full)
        d11, d22, d12, d33 = st.coeffs.T.real
        ds = np.column_stack([d11 * eps[:, 0] + d12 * eps[:, 1], d12 * eps[:, 0] + d22 * eps[:, 1], d33 * eps[:, 2]])
        s0 = self.ground.initial_stress(values, -self.fe.centroid[:, 1], self.fe.region)
        return s0 + ds


def build_domain(loaded, mesh: Mesh | None = None, blocks=None, backend: str | None = None,
                 extensions: Mapping | None = None) -> Domain:
    """The domain of a case: its mesh (`mesh`, or meshed), FE model, ground with the extension table
    `extensions`, construction plan and the survey of `blocks` (default: every instrument of the case
    at the last stage; a block read at a stage the plan lacks is refused before meshing)."""
    case = loaded.case
    plan = StagePlan.of(case)
    stages = list(plan.names)
    if blocks is not None:
        refuse_late_blocks(loaded, blocks, stages)
    t0 = time.perf_counter()
    mesh = mesh or build_mesh(case, allow_large=getattr(loaded, "allow_large", False))
    t1 = time.perf_counter()
    g = case.geometry
    fe = FEModel(mesh, g.width, g.depth, (0.0, -g.axis_depth), g.radius)
    t2 = time.perf_counter()
    ground = Ground(case, -fe.centroid[:, 1], fe.region, -fe.wall_points[:, 1], extensions or {})
    survey = stage_survey(loaded, blocks, stages, fe)
    timings = {"mesh": t1 - t0, "assembly": t2 - t1, "observations": time.perf_counter() - t2}
    return Domain(loaded, mesh, fe, ground, plan, survey, Counters(), timings, backend)
