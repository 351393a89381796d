"""Physics behind one interface.

A *simulation* is built from a case and a mesh and answers one question: the readings of its
survey, and their sensitivities, at given named values,

    x(v) = P u(v) - G c,      A = dx/dv   (eqns 29, 31-42),

with its counters of factorisations and solves. Named values are the ground's (``E[clay]``,
``K0``, ...), the extensions' (``Egrad[clay]``, ``beta``, ...) and the instruments' integration
constants (``B[I1]``, ...). Statistics, diagnosis and reports see only this interface.

Implementations (registered in ``factory.IMPLEMENTATIONS``, checked by one contract test): the
one-step linear-elastic excavation (``elastic.py``), staged construction with a lining
(``staged.py``) and elastoplastic ground (``plastic.py``). Each is composed of the same parts: a
``Domain`` (``domain.py``, built by ``build_domain``: mesh, FE model, ground, construction plan,
survey, counters), the ``Names`` it honours (``names.py``) and components of its own physics
(``stiffness.FactorCache``, ``lined_system.LinedSystem``, the plastic run memo).
"""
from __future__ import annotations

import contextlib
import copy
import time
from abc import ABC, abstractmethod
from dataclasses import replace, dataclass, field
from typing import Mapping, Sequence

import numpy as np

from geoback.observation.instruments import CONSTANT_STEMS, Survey, is_instrument_error


@dataclass
class Counters:
    """What a simulation has spent: factorisations, back-substitutions, forward runs, seconds."""

    factorisations: int = 0
    solves: int = 0  # right-hand sides back-substituted
    forward_runs: int = 0
    seconds_factorising: float = 0.0
    seconds_solving: float = 0.0
    seconds_assembling: float = 0.0
    factorised_unknowns: int = 0  # summed over the factorisations: their mean size is this / factorisations
    condensations: int = 0  # elastic parts condensed onto the region that may yield (plasticity/condensed.py)
    analyses: int = 0  # symbolic analyses of a sparsity pattern by an elastoplastic engine (plasticity/linear.py)

    def add_engine(self, c) -> None:
        """Add what an elastoplastic engine run spent (``plasticity.linear.Counters``)."""
        if c is None:
            return
        self.factorisations += c.factorisations
        self.factorised_unknowns += c.factorised_unknowns
        self.condensations += c.condensations
        self.analyses += c.analyses
        self.solves += c.backsubstitutions
        self.seconds_factorising += c.seconds.get("factorise", 0.0) + c.seconds.get("condense", 0.0)
        self.seconds_solving += c.seconds.get("backsubstitute", 0.0) + c.seconds.get("backsubstitute: elastic part", 0.0)
        self.seconds_assembling += c.seconds.get("assemble tangent", 0.0)

    def snapshot(self) -> dict:
        return dict(vars(self))

    def since(self, before: dict) -> dict:
        """The counts spent since `before` (a snapshot)."""
        return {k: v - before.get(k, 0) for k, v in vars(self).items()}


@dataclass(frozen=True)
class Prediction:
    """Computed readings x and, if asked, A = dx/dv for the names asked (physical units)."""

    x: np.ndarray
    A: np.ndarray | None = None


@dataclass(frozen=True)
class Field:
    """A solution on the mesh, for outputs: nodal displacement (N, 2), cell data by name and more
    point data by name (e.g. the displacement after every construction stage)."""

    mesh: object
    displacement: np.ndarray
    cell_data: dict = field(default_factory=dict)
    point_data: dict = field(default_factory=dict)


def is_constant(name: str) -> bool:
    """Integration constants of linewise instruments: A[X1], B[I1], C[D1], D[D1]."""
    return name.split("[")[0] in CONSTANT_STEMS and name.endswith("]")


def is_instrument_term(name: str) -> bool:
    """Names the survey owns rather than the physics: integration constants (A[X1], B[I1], ...) and
    inclinometers' systematic errors (bias[I1], zoff[I1])."""
    return is_constant(name) or is_instrument_error(name)


def _of_domain(name: str, doc: str) -> property:
    """A read-only attribute of the simulation that is its domain's."""
    return property(lambda self: getattr(self.domain, name), doc=doc)


class Simulation(ABC):
    """Readings of a survey and their sensitivities at named values (see the module docstring).

    A simulation holds its ``Domain`` (``domain.py``: mesh, FE model, ground, construction plan,
    survey, counters) and its ``Names`` (``names.py``: quantities, canonical names, units, ranges and
    null values); implementations provide the physics: ``_readings`` (x = P u and its sensitivity),
    ``stage_displacements`` and ``field``. This class adds the instruments' integration constants
    (x -= G c, eqns 11, 15, 18), which no physics needs to know about.

    State is kept in two kinds of attribute: components named in ``SHARED`` hold what does not depend
    on the survey (factorisations, the last solution), and are shared by a view on other instruments
    (``surveying``) and copied by ``copy.copy``; attributes named in ``SURVEY_CACHES`` hold results per
    survey row, re-derived when the survey changes (``_survey_changed``).
    """

    reads_depth_offsets: bool = False  # _readings observes with survey.operator(values) (zoff[I1] available)
    # readings only piecewise smooth in the values (ground switching between elastic and plastic): J has
    # kinks, so an optimiser stops once J no longer falls by a meaningful amount (estimate.PIECEWISE_TOL)
    piecewise_smooth: bool = False
    SHARED: tuple[str, ...] = ()  # components with survey-independent state (shared by views)
    SURVEY_CACHES: tuple[str, ...] = ()  # attributes holding results per survey row

    def __init__(self, domain, names):
        self.domain = domain  # geoback.physics.domain.Domain
        self.names = names  # geoback.physics.names.Names

    # ------------------------------------------------------------------ the domain
    loaded = _of_domain("loaded", "The LoadedCase the simulation was built from.")
    mesh = _of_domain("mesh", "The ground's mesh (``mesh.Mesh``).")
    fe = _of_domain("fe", "The FE model (``fem.FEModel``).")
    ground = _of_domain("ground", "The ground as a function of the named values (``ground.Ground``).")
    plan = _of_domain("plan", "The construction plan (``construction.StagePlan``).")
    counters = _of_domain("counters", "What the simulation (and its views) have spent (``Counters``).")
    timings = _of_domain("timings", "Seconds of the set-up: mesh, assembly, observations (and more by physics).")
    backend = _of_domain("backend", "The sparse solver asked for (None: chosen by size).")

    @property
    def survey(self) -> Survey:
        return self.domain.survey

    @survey.setter
    def survey(self, survey: Survey) -> None:
        self.domain = self.domain.with_survey(survey)
        self._survey_changed()

    @property
    def stages(self) -> list[str]:
        """Construction stages the simulation computes, in order (readings are taken at them)."""
        return self.domain.stages

    @property
    def dofs(self) -> int:
        return self.fe.ndof

    @property
    def solver(self) -> str | None:
        """The sparse solver that factorised (None before any factorisation)."""
        return None

    # ------------------------------------------------------------------ names
    def quantities(self) -> dict[str, float]:
        """Every named physical value of the case, at the case's values."""
        return self.names.quantities()

    def canonical(self, name: str) -> str | None:
        """Full name of a physical quantity ('E' -> 'E[clay]' for one layer); None if unknown."""
        return self.names.canonical(name)

    def null_value(self, name: str, values: Mapping) -> float | None:
        """Value of an extension quantity at which the model is the baseline; None if not one."""
        return self.names.null_value(name, values)

    def unit(self, name: str) -> str:
        """Unit of a physical quantity."""
        return self.names.unit(name)

    def limits(self, name: str, values: Mapping):
        """Allowed and usual range of a physical quantity (``limits.Limits``)."""
        return self.names.limits(name, values)

    def known_names(self) -> list[str]:
        """Examples of valid names, for messages."""
        return sorted(self.quantities()) + list(self.survey.constant_names) + list(self.survey.error_names)

    # ------------------------------------------------------------------ predictions
    @abstractmethod
    def _readings(self, values: Mapping, wrt: Sequence[str]) -> Prediction:
        """x = P u(values) and, for the physical names in `wrt`, its sensitivity columns."""

    @abstractmethod
    def field(self, values: Mapping) -> Field:
        """Displacement and stress fields at `values` (outputs; not needed by a fit)."""

    @abstractmethod
    def stage_displacements(self, values: Mapping) -> np.ndarray:
        """u_k on the free dofs after every construction stage (nstages, nfree)."""

    def displacement(self, values: Mapping) -> np.ndarray:
        """u on the free dofs after the last stage."""
        return self.stage_displacements(values)[-1]

    def stage_displacements_at(self, values: Mapping, points: np.ndarray, stage: str) -> np.ndarray:
        """(ux, uy) at points (k, 2) of the ground accumulated up to construction stage `stage`;
        ValueError for a point outside the ground or a stage the simulation does not compute."""
        if stage not in self.stages:
            computes = (f"stage '{self.stages[-1]}' only" if len(self.stages) == 1
                        else f"stages {', '.join(self.stages)}")
            raise ValueError(f"this simulation computes {computes}, not '{stage}'")
        Ix, Iy = self.fe.interpolation(points)
        u = self.stage_displacements(values)[self.stages.index(stage)]
        return np.column_stack([Ix @ u, Iy @ u])

    def displacements_at(self, values: Mapping, points: np.ndarray) -> np.ndarray:
        """(ux, uy) at points (k, 2) of the ground after the last stage; ValueError for a point outside it."""
        return self.stage_displacements_at(values, points, self.stages[-1])

    def lining_forces(self, values: Mapping):
        """Thrust, shear and bending moment around the lining per stage (``lining.LiningForces``);
        None for a model without a lining."""
        return None

    def plastic_zone(self, values: Mapping):
        """The yielded ground after every stage (``plastic_zone.PlasticZone``); None for a model
        whose ground cannot yield."""
        return None

    def predict(self, values: Mapping, wrt: Sequence[str] = (), sensitivities: bool = False) -> Prediction:
        """Readings at `values` (constants A-D and the inclinometers' bias and zoff default to 0);
        with `sensitivities`, A = dx/d(wrt).

        The physics computes every row of ``survey.operator(values)`` (the readings, read at the
        inclinometers' depth offsets, and below them their depth derivatives D u); here
        x = P u - G c + E b, dx/d zoff = D u (exact)."""
        survey = self.survey
        physical = [n for n in wrt if not is_instrument_term(n)] if sensitivities else []
        if not self.reads_depth_offsets and (survey.offsets(values) or any(n in survey.depth_rows for n in wrt)):
            raise NotImplementedError(f"{type(self).__name__} does not read the survey at depth offsets: "
                                      f"inclinometer depth offsets (zoff) are not available with it")
        pred = self._increments(values, physical, self._readings(values, physical))
        m = survey.m
        x = pred.x[:m]
        A_phys = pred.A[:m] if sensitivities and pred.A is not None else None
        for name, v in values.items():  # (another instrument's terms: not this survey's readings, e.g. a view's)
            if v == 0:
                continue
            if is_constant(name) and name in survey.constant_names:
                x = x - survey.G[:, survey.constant_names.index(name)] * v
            elif name.startswith("bias[") and name in survey.error_names:
                x = x + survey.bias_column(name) * v
        if not sensitivities:
            return Prediction(x)
        A = np.zeros((len(x), len(wrt)))
        k = 0
        for j, name in enumerate(wrt):  # an instrument term of another survey's instrument: a zero column
            if is_constant(name):
                if name in survey.constant_names:
                    A[:, j] = survey.constant_column(name)
            elif name in survey.depth_rows:
                rows, extra = survey.depth_rows[name]
                A[rows, j] = pred.x[extra]
            elif is_instrument_error(name):
                if name.startswith("bias[") and name in survey.error_names:
                    A[:, j] = survey.bias_column(name)
            else:
                A[:, j] = A_phys[:, k]
                k += 1
        return Prediction(x, A)

    def _increments(self, values: Mapping, physical: Sequence[str], pred: Prediction) -> Prediction:
        """Instruments installed after a stage read increments since then: x = P (u_k - u_since)
        (their rows of ``operator``, depth-derivative rows included), from a view reading the same
        instruments at their installation stage (the same factorisations and runs)."""
        survey = self.survey
        if not any(b.since is not None for b in survey.blocks):
            return pred
        cached = self.__dict__.get("_installation")
        if cached is None or cached[0] is not survey:
            blocks = [replace(b.at(b.since), since=None) if b.since is not None else b for b in survey.blocks]
            view = self._sharing()
            view.domain = self.domain.reading(blocks)
            view._survey_changed()
            view.__dict__.pop("_installation", None)
            mask = np.zeros(len(pred.x), bool)
            r0 = 0
            for b in survey.blocks:
                if b.since is not None:
                    mask[r0:r0 + b.m] = True
                    rows = survey.depth_rows.get(f"zoff[{b.name}]")
                    if rows is not None:
                        mask[rows[1]] = True
                r0 += b.m
            cached = (survey, view, mask)
            self.__dict__["_installation"] = cached
        _, view, mask = cached
        base = view._readings(values, physical)
        x = pred.x - np.where(mask, base.x, 0.0)
        A = None if pred.A is None else pred.A - np.where(mask[:, None], base.A, 0.0)
        return Prediction(x, A)

    def release(self) -> None:
        """Free memory held by factorisations (the simulation stays usable)."""

    def probing(self):
        """A context in which readings asked without sensitivities are probes (an interval's check) and not an
        optimiser's trial points, which a non-linear simulation may differentiate ahead in case one is accepted
        (``plastic.Runs``): there it does not."""
        return contextlib.nullcontext()

    def replaying(self, values: Mapping) -> "Simulation":
        """A simulation whose readings near `values` are the same discrete function of the values as
        this one's at `values`, to take finite differences of (what the sensitivities are exact
        derivatives of): this simulation itself when its discretisation does not depend on the values
        (linear physics)."""
        return self

    # ------------------------------------------------------------------ other instruments
    def surveying(self, blocks) -> "Simulation":
        """A view of the simulation reading other instruments (forecast points, candidate instruments):
        a new simulation of the same domain with the survey of `blocks`, sharing the factorisations,
        the remembered solutions (``SHARED``) and the counters; the simulation itself is untouched.

            view = simulation.surveying(blocks)
            q = view.predict(values, names, sensitivities=True)

        A view is also a context manager (``with simulation.surveying(blocks) as view:``)."""
        view = self._sharing()
        view.domain = self.domain.reading(blocks)
        view._survey_changed()
        return view

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> bool:
        return False

    def __copy__(self):
        """An independent simulation of the same domain, starting from this one's state: its
        ``SHARED`` components copied, so that what it factorises, remembers or is set to is its own
        (the counters stay shared)."""
        new = self._sharing()
        for name in self.SHARED:
            setattr(new, name, copy.copy(getattr(self, name)))
        return new

    def _sharing(self):
        """A new simulation object with this one's attributes (the components themselves shared)."""
        other = object.__new__(type(self))
        other.__dict__.update(self.__dict__)
        return other

    def _survey_changed(self) -> None:
        """Re-derive what SURVEY_CACHES hold for a new survey (the old values still in place); by
        default they are forgotten."""
        for name in self.SURVEY_CACHES:
            setattr(self, name, None)


class Stopwatch:
    """Adds elapsed seconds to a counter attribute: ``with Stopwatch(counters, 'seconds_solving'):``."""

    def __init__(self, counters: Counters, attr: str):
        self.counters, self.attr = counters, attr

    def __enter__(self):
        self.t0 = time.perf_counter()
        return self

    def __exit__(self, *exc):
        setattr(self.counters, self.attr, getattr(self.counters, self.attr) + time.perf_counter() - self.t0)
        return False


def refuse_late_blocks(loaded, blocks, stages: list[str]) -> None:
    """A block read at a stage the simulation does not compute is refused, located in the case."""
    late = [b for b in blocks if b.stage not in stages]
    if late:
        expected = (f"expected one of the construction stages ({', '.join(stages)})" if len(stages) > 1
                    else f"the case has one construction stage ('{stages[-1]}')")
        raise loaded.error(("instruments", late[0].index, "readings"),
                           f"readings of '{late[0].name}' at stage '{late[0].stage}': {expected}")


def stage_survey(loaded, blocks, stages: list[str], fe) -> Survey:
    """The survey of `blocks` on the FE model `fe` (default: every instrument of the case read at the
    last stage); a block read at a stage the simulation does not compute is refused, located."""
    from geoback.observation.instruments import build_survey, case_blocks

    from geoback.physics.fem import OutsideMesh

    blocks = blocks if blocks is not None else [b.at(stages[-1]) for b in case_blocks(loaded)]
    refuse_late_blocks(loaded, blocks, stages)
    try:
        return build_survey(blocks, fe)
    except OutsideMesh as exc:  # the case's checks passed it: said with the instrument it belongs to
        b = next((b for b in blocks if np.any(np.all(np.isclose(b.points, exc.point, rtol=0, atol=1e-12), axis=1))),
                 None)
        if b is None:
            raise
        x, y = exc.point
        raise loaded.error(("instruments", b.index),
                           f"expected every point instrument '{b.name}' reads inside the meshed ground, found "
                           f"({x:g}, {y:g}) outside it; move the instrument into the ground (off the tunnel wall "
                           f"and the model's edges)") from None
