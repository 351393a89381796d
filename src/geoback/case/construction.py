"""Staged construction as data: which stress fraction each stage releases and which stiffness
configuration carries it. No finite elements here: the plan is shared by every simulation that
runs stages (the linear-elastic ``staged.py`` today, an elastoplastic one later).

A case's ``construction:`` section lists stages in order. Stage k releases the in-situ stress on
the tunnel wall up to the cumulative fraction beta_k (convergence-confinement: beta is what the
ground took before the support acts, the face effect), so its load is (beta_k - beta_(k-1)) f with
f the full release load of eqn 33; a stage may first install the lining, which is then part of
the stiffness for that stage's release and every later one. Readings of stage k are the
displacements accumulated up to it (DESIGN.md):

    u_k = sum_{j <= k} (beta_j - beta_(j-1)) K_c(j)^-1 f = sum_c a_kc w_c,    w_c = K_c^-1 f,

with c(j) the configuration of stage j (0: the ground alone, 1: ground and lining) and a_kc the
fraction released under configuration c up to stage k. The named values are ``beta[stage]`` for
every stage that releases, and ``E[lining]``, ``nu[lining]`` for the lining.

A case without a construction section is one stage, 'excavation', releasing everything.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from geoback.case.limits import LINING, QUANTITIES, Limits
from geoback.case.schema import Case, number_text

DEFAULT_STAGE = "excavation"
MAX_ASPECT = 20.0  # lining elements: length along the wall over thickness


def stage_names(case: Case) -> list[str]:
    """Names of the construction stages, in construction order."""
    if case.construction is None:
        return [DEFAULT_STAGE]
    return [s.name for s in case.construction.stages]


def beta_name(stage: str) -> str:
    return f"beta[{stage}]"


@dataclass(frozen=True)
class StagePlan:
    """The construction sequence of a case: stage names, the parameter of each stage's release
    (None where a stage releases nothing), whether the lining acts during each stage's release,
    and the lining (a case_schema.Lining, or None)."""

    names: tuple[str, ...]
    release: tuple[str | None, ...]
    values: dict  # beta[stage] -> the case's value
    lined: tuple[bool, ...]
    lining: object | None
    installed_at: int | None  # index of the stage that installs the lining

    CONFIGURATIONS = ("ground", "ground and lining")

    @classmethod
    def of(cls, case: Case) -> "StagePlan":
        if case.construction is None:
            return cls((DEFAULT_STAGE,), (None,), {}, (False,), None, None)
        c = case.construction
        release, values, lined, at = [], {}, [], None
        for k, s in enumerate(c.stages):
            if s.install is not None:
                at = k
            lined.append(at is not None)
            if s.release is None:
                release.append(None)
            else:
                release.append(beta_name(s.name))
                values[beta_name(s.name)] = float(s.release)
        return cls(tuple(s.name for s in c.stages), tuple(release), values, tuple(lined), c.lining, at)

    # ------------------------------------------------------------------ names
    @property
    def staged(self) -> bool:
        """Has the case a construction section (or the default single excavation)?"""
        return bool(self.values)

    @property
    def lining_name(self) -> str | None:
        return self.lining.name if self.lining is not None else None

    def lining_names(self) -> list[str]:
        n = self.lining_name
        return [f"E[{n}]", f"nu[{n}]"] if n else []

    def quantities(self) -> dict[str, float]:
        """beta[stage] of every releasing stage and the lining's E and nu, at the case's values."""
        out = dict(self.values)
        if self.lining is not None:
            out[f"E[{self.lining.name}]"] = float(self.lining.E)
            out[f"nu[{self.lining.name}]"] = float(self.lining.nu)
        return out

    def knows(self, name: str) -> bool:
        return name in self.values or name in self.lining_names()

    def canonical(self, name: str) -> str | None:
        """The name itself if the plan owns it (stages' releases and the lining's values are always
        written in full), else None."""
        return name if self.knows(name) else None

    def unit(self, name: str) -> str | None:
        return self._table(name)[name.partition("[")[0]][0] if self.knows(name) else None

    def limits(self, name: str, values: Mapping) -> Limits | None:
        """Allowed and usual range of a release (``limits.QUANTITIES``) or a lining value (``limits.LINING``:
        concrete's usual moduli, not the ground's, so that a modulus in MPa where GPa was meant is said)."""
        return self._table(name)[name.partition("[")[0]][1] if self.knows(name) else None

    def _table(self, name: str) -> dict:
        return LINING if name in self.lining_names() else QUANTITIES

    @property
    def configurations(self) -> list[int]:
        """Configurations used by a stage that releases stress, in order of first use."""
        used = [int(lined) for lined, r in zip(self.lined, self.release) if r is not None]
        return list(dict.fromkeys(used))

    def last_release_before_lining(self) -> str | None:
        """beta[stage] of the last stage whose release the ground takes alone (the CCM's beta)."""
        if self.installed_at is None:
            return None
        before = [r for r, lined in zip(self.release, self.lined) if r is not None and not lined]
        return before[-1] if before else None

    # ------------------------------------------------------------------ the release sequence
    def cumulative(self, values: Mapping) -> np.ndarray:
        """beta_k after every stage (a stage that releases nothing keeps the previous fraction);
        complex-safe. A case without construction releases everything in its one stage."""
        if not self.staged:
            return np.ones(1)
        dtype = complex if any(isinstance(values.get(r), complex) for r in self.release if r) else float
        out, b = np.zeros(len(self.names), dtype), 0.0
        for k, r in enumerate(self.release):
            if r is not None:
                b = values[r]
            out[k] = b
        return out

    def weights(self, values: Mapping) -> np.ndarray:
        """a[k, c]: fraction of the in-situ wall stress released under configuration c (0 ground,
        1 ground and lining) up to and including stage k."""
        beta = self.cumulative(values)
        inc = np.diff(np.concatenate([[0.0], beta]))
        a = np.zeros((len(self.names), 2), dtype=beta.dtype)
        for k in range(len(self.names)):
            a[k, int(self.lined[k])] += inc[k]
            if k:
                a[k] += a[k - 1]
        return a

    def weights_derivative(self, name: str) -> np.ndarray:
        """d a / d beta[stage] (the map is linear)."""
        base = {r: 0.0 for r in self.release if r}
        base[name] = 1.0
        return self.weights(base)


# ---------------------------------------------------------------------------- checks of a case
def construction_problems(case: Case) -> list[tuple[tuple, str]]:
    """Checks of the construction section pydantic cannot express: (path, message) for each."""
    c = case.construction
    if c is None:
        return []
    at, out = ("construction",), []
    for field in ("linings", "walls", "props", "anchors"):
        if getattr(c, field):
            out.append((at + (field,), f"expected '{field}:' only in a case with openings (geometry: {{model, width, "
                                       f"depth, openings}}), found it with a circular tunnel"))
    names = [s.name for s in c.stages]
    for i, n in enumerate(names):
        if names.index(n) != i:
            out.append((at + ("stages", i, "name"), f"expected unique stage names, found '{n}' again "
                                                    f"(as in construction.stages[{names.index(n)}])"))
    previous, prev_at = 0.0, None
    for i, s in enumerate(c.stages):
        here = at + ("stages", i)
        if s.release is None and s.install is None:
            out.append((here, f"expected a stage that does something: a 'release' (cumulative fraction of the "
                              f"in-situ stress) or an 'install' (the lining), found neither in stage '{s.name}'"))
        if s.release is not None:
            if s.release <= previous:
                out.append((here + ("release",),
                            f"expected a release greater than that of stage '{prev_at}' ({number_text(previous)}): releases "
                            f"are cumulative fractions of the in-situ stress, found {number_text(s.release)}"))
            previous, prev_at = s.release, s.name
    if not any(s.release is not None for s in c.stages):
        out.append((at + ("stages",), "expected at least one stage with a 'release', found none"))
    installs = [i for i, s in enumerate(c.stages) if s.install is not None]
    lining = c.lining
    for i in installs:
        s = c.stages[i]
        if lining is None:
            out.append((at + ("stages", i, "install"),
                        f"expected the name of a lining defined in construction.lining, found '{s.install}' "
                        f"and no lining section"))
        elif s.install != lining.name:
            out.append((at + ("stages", i, "install"),
                        f"expected the lining's name '{lining.name}', found '{s.install}'"))
    if lining is not None:
        if not installs:
            out.append((at + ("lining",), f"expected the lining '{lining.name}' to be installed by a stage "
                                          f"('install: {lining.name}'), found no stage installing it"))
        elif len(installs) > 1:
            out.append((at + ("stages", installs[1], "install"),
                        f"expected the lining to be installed once, found it installed again "
                        f"(already in stage '{c.stages[installs[0]].name}')"))
        elif not any(s.release is not None for s in c.stages[installs[0]:]):
            out.append((at + ("stages", installs[0], "install"),
                        f"expected a release at or after the stage installing the lining: installed after the "
                        f"last release, the lining '{lining.name}' would carry no load"))
        g = case.geometry
        if lining.thickness >= 0.5 * g.radius:
            out.append((at + ("lining", "thickness"),
                        f"expected a lining thinner than half the tunnel radius ({number_text(0.5 * g.radius)} m), "
                        f"found thickness {number_text(lining.thickness)}"))
        if case.mesh.order != 2:
            out.append((("mesh", "order"), "expected quadratic elements (order: 2) with a lining: linear "
                                           "triangles lock in bending, found order 1"))
        if lining.name in [layer.name for layer in case.ground.layers]:
            out.append((at + ("lining", "name"), f"expected a lining name different from the ground layers' "
                                                 f"names, found '{lining.name}' (a layer's name)"))
        size = case.mesh.size_tunnel or g.radius / 8
        element = lining.thickness / lining.layers
        if size / element > MAX_ASPECT:
            out.append((("mesh", "size_tunnel"),
                        f"expected lining elements at most {MAX_ASPECT:g} times longer than thick: with thickness "
                        f"{number_text(lining.thickness)} m in {lining.layers} layer(s), size_tunnel at most "
                        f"{number_text(MAX_ASPECT * element)} m, found {number_text(size)}"))
    return out
