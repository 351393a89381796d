"""The construction of a case with openings as data: what each stage removes, installs and releases.
No finite elements here (``physics/excavation.py`` runs it).

A stage first removes the parts (or whole openings) in its ``excavate`` and the linings in its
``remove``; the load those elements exerted on the ground that remains (their internal force from
their current stress less their weight) forms the stage's *release group*. It then installs the
linings in ``install`` (stress-free, on the ground as it has moved) and releases loads:

- a stage that removes something releases its own group up to ``release`` (default 1: all of it);
  ``release: 0.4`` leaves 60 % held, as a support pressure would (the face effect, beta);
- a stage that removes nothing releases every group still *open* (created with an explicit
  ``release``) up to its ``release`` (default 1), typically after installing the lining.

A stage's explicit release is the named value ``beta[stage]``; each lining's ``E[lining]`` and
``nu[lining]`` are named values too. ``fractions(values)`` gives the cumulative fraction released of
every group after every stage: the only thing the values change in the sequence (complex-safe).
A case with openings and no construction section is one stage, 'excavation', removing every opening.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from geoback.case.limits import QUANTITIES, Limits
from geoback.case.schema import Case, number_text

DEFAULT_STAGE = "excavation"


def beta_name(stage: str) -> str:
    return f"beta[{stage}]"


@dataclass(frozen=True)
class Step:
    """One stage: the regions it excavates and linings it removes (by name), the linings it installs,
    the parameter of its release (None: the default 1) and the release groups it releases."""

    name: str
    excavate: tuple[str, ...]
    remove: tuple[str, ...]
    install: tuple[str, ...]
    release: str | None
    releases: tuple[int, ...]  # indices of the groups this stage's release applies to


@dataclass(frozen=True)
class Sequence:
    """The construction of a case with openings (module docstring). `groups[g]` is the stage index that
    created release group g (group g of the stage's removals)."""

    steps: tuple[Step, ...]
    groups: tuple[int, ...]
    values: dict
    linings: dict  # name -> schema.PlacedLining
    walls: dict = None  # name -> supports.WallBand
    connectors: dict = None  # name -> supports.Connector (props and anchors)

    def installed_at(self, name: str) -> int:
        """The stage that installs a lining, wall, prop or anchor (-1: a wall in place from the start)."""
        return next((k for k, s in enumerate(self.steps) if name in s.install), -1)

    @property
    def bands(self) -> tuple[str, ...]:
        """What the mesh holds as bands of elements: the linings, then the walls."""
        return tuple(self.linings) + tuple(self.walls or {})

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.steps)

    @classmethod
    def of(cls, case: Case) -> "Sequence":
        from geoback.case.layout import regions

        layout = case.geometry
        c = case.construction
        expand = _expander(layout)
        if c is None:
            everything = tuple(n for op in layout.openings for n in expand(op.name))
            return cls((Step(DEFAULT_STAGE, everything, (), (), None, (0,)),), (0,), {}, {}, {}, {})
        steps, groups, values, open_groups = [], [], {}, []
        for k, s in enumerate(c.stages):
            excavate = tuple(n for name in (s.excavate or []) for n in expand(name))
            remove = tuple(s.remove or [])
            install = tuple([s.install] if isinstance(s.install, str) else (s.install or []))
            release = beta_name(s.name) if s.release is not None else None
            if release:
                values[release] = float(s.release)
            if excavate or remove:
                groups.append(k)
                g = len(groups) - 1
                releases = (g,)
                if release:
                    open_groups.append(g)
            else:
                releases = tuple(open_groups)
                if not release:
                    open_groups = []
            steps.append(Step(s.name, excavate, remove, install, release, releases))
        from geoback.case.supports import connectors, walls

        return cls(tuple(steps), tuple(groups), values, {ln.name: ln for ln in (c.linings or [])}, walls(case),
                   connectors(case))

    # ------------------------------------------------------------------ names (a source for physics.names.Names)
    def lining_names(self) -> list[str]:
        return [f"{q}[{n}]" for n in self.linings for q in ("E", "nu")]

    def structure_names(self) -> list[str]:
        """E[wall], nu[wall] of every wall; k[support], preload[support] of every prop and anchor."""
        return ([f"{q}[{n}]" for n in (self.walls or {}) for q in ("E", "nu")]
                + [f"{q}[{n}]" for n in (self.connectors or {}) for q in ("k", "preload")])

    def quantities(self) -> dict[str, float]:
        out = dict(self.values)
        for n, ln in self.linings.items():
            out[f"E[{n}]"], out[f"nu[{n}]"] = float(ln.E), float(ln.nu)
        for n, w in (self.walls or {}).items():
            out[f"E[{n}]"], out[f"nu[{n}]"] = w.E, w.nu
        for n, cn in (self.connectors or {}).items():
            out[f"k[{n}]"], out[f"preload[{n}]"] = cn.stiffness, cn.preload
        return out

    def knows(self, name: str) -> bool:
        return name in self.values or name in self.lining_names() or name in self.structure_names()

    def canonical(self, name: str) -> str | None:
        return name if self.knows(name) else None

    def _table(self, name: str) -> dict:
        from geoback.case.limits import SUPPORT, WALL

        stem, _, owner = name.partition("[")
        owner = owner[:-1]
        if owner in (self.walls or {}):
            return WALL
        if owner in (self.connectors or {}):
            return SUPPORT
        return QUANTITIES

    def unit(self, name: str) -> str | None:
        return self._table(name)[name.partition("[")[0]][0] if self.knows(name) else None

    def limits(self, name: str, values: Mapping) -> Limits | None:
        return self._table(name)[name.partition("[")[0]][1] if self.knows(name) else None

    # ------------------------------------------------------------------ the releases
    def fractions(self, values: Mapping) -> np.ndarray:
        """(nstages, ngroups) cumulative fraction of each group's load released after each stage."""
        dtype = complex if any(isinstance(values.get(s.release), complex) for s in self.steps if s.release) else float
        out = np.zeros((len(self.steps), len(self.groups)), dtype)
        for k, s in enumerate(self.steps):
            if k:
                out[k] = out[k - 1]
            b = values[s.release] if s.release else 1.0
            for g in s.releases:
                out[k, g] = b
        return out

    def describe(self) -> list[str]:
        """The construction in words, one line a stage, defaults said (what `validate` echoes)."""
        frac = self.fractions(self.values)
        lines = [f"wall '{n}' ({number_text(w.thickness)} m thick, E = {number_text(round(w.E / 1e6, 6))} GPa, from "
                 f"{number_text(w.top)} "
                 f"to {number_text(w.toe)} m depth at x = {number_text(w.x)}) in place from the start"
                 for n, w in (self.walls or {}).items() if self.installed_at(n) < 0]

        def named(n):
            cn = (self.connectors or {}).get(n)
            if cn is None:
                return n
            return (f"{n} ({cn.kind} on '{cn.wall}' at {number_text(-cn.head[1])} m depth to {cn.far}, "
                    f"k = {number_text(round(cn.stiffness, 6))} kN/m/m, preload {number_text(cn.preload)} kN/m)")


        for k, st in enumerate(self.steps):
            did = []
            if st.excavate:
                did.append("excavates " + ", ".join(st.excavate))
            if st.remove:
                did.append("removes " + ", ".join(st.remove))
            if st.install:
                did.append("installs " + ", ".join(named(n) for n in st.install))
            released = []
            for g in st.releases:
                what = "its load" if self.groups[g] == k else f"the load of stage '{self.steps[self.groups[g]].name}'"
                how = f"{st.release}" if st.release else "by default"
                released.append(f"{what} to {100 * float(frac[k, g]):g} % ({how})")
            if released:
                did.append("releases " + "; ".join(released))
            lines.append(f"stage '{st.name}': " + (", ".join(did) if did else "nothing"))
        held = [g for g in range(len(self.groups)) if float(frac[-1, g]) < 1.0]
        for g in held:
            lines.append(f"at the last stage {100 * (1 - float(frac[-1, g])):g} % of the load of stage "
                         f"'{self.steps[self.groups[g]].name}' is still held (not released)")
        return lines

    def fractions_derivative(self, name: str) -> np.ndarray:
        """d fractions / d beta[stage] (the map is linear in each beta)."""
        base = {s.release: 0.0 for s in self.steps if s.release}
        base[name] = 1.0
        ones = self.fractions({s.release: 0.0 for s in self.steps if s.release})
        return self.fractions(base) - ones


def _expander(layout):
    """name -> the regions it excavates: an opening with parts stands for all of them."""
    def expand(name: str) -> tuple[str, ...]:
        op = next((o for o in layout.openings if o.name == name), None)
        if op is not None and op.parts:
            return tuple(p.name for p in op.parts)
        return (name,)
    return expand


# ---------------------------------------------------------------------------- checks
def sequence_problems(case: Case) -> list[tuple[tuple, str]]:
    """Checks of the construction of a case with openings: (path, message) for each problem."""
    from geoback.case.layout import lining_band, regions

    c, layout = case.construction, case.geometry
    if c is None:
        return []
    at, out = ("construction",), []
    if c.lining is not None:
        out.append((at + ("lining",), "expected 'linings:' (a list, each placed 'on' an opening or part) with "
                                      "openings, found 'lining:'"))
    known = set(regions(layout)) | {op.name for op in layout.openings}
    expand = _expander(layout)
    linings = {ln.name: (j, ln) for j, ln in enumerate(c.linings or [])}
    structures = {x.name for x in (c.walls or []) + (c.props or []) + (c.anchors or [])}
    for j, ln in enumerate(c.linings or []):
        where = at + ("linings", j)
        if ln.on not in known:
            out.append((where + ("on",), f"expected the name of an opening or part ({', '.join(sorted(known))}), "
                                         f"found '{ln.on}'"))
            continue
        if ln.side == "cut" and any(op.name == ln.on for op in layout.openings):
            out.append((where + ("side",), f"expected a part for a lining along cut lines, found opening '{ln.on}'"))
            continue
        try:
            area = lining_band(layout, ln).area
        except Exception:  # noqa: BLE001 - a degenerate band: said below
            area = 0.0
        if not area > 0:
            out.append((where, f"expected lining '{ln.name}' to occupy a band of the {ln.side} of '{ln.on}', found "
                               f"none (no {'cut line along that part' if ln.side == 'cut' else 'wall'})"))
        if case.mesh.order != 2:
            out.append((("mesh", "order"), "expected quadratic elements (order: 2) with a lining: linear "
                                           "triangles lock in bending, found order 1"))
    names = [s.name for s in c.stages]
    excavated: dict[str, int] = {}
    installed: dict[str, int] = {}
    removed: dict[str, int] = {}
    open_groups = False
    for i, s in enumerate(c.stages):
        here = at + ("stages", i)
        if names.index(s.name) != i:
            out.append((here + ("name",), f"expected unique stage names, found '{s.name}' again"))
        if not (s.excavate or s.remove or s.install or s.release is not None):
            out.append((here, f"expected a stage that does something (excavate, install, remove or release), found "
                              f"none of them in stage '{s.name}'"))
        for j, n in enumerate(s.excavate or []):
            if n not in known:
                out.append((here + ("excavate", j), f"expected the name of an opening or part "
                                                    f"({', '.join(sorted(known))}), found '{n}'"))
                continue
            for r in expand(n):
                if r in excavated:
                    out.append((here + ("excavate", j), f"expected each part excavated once, found '{r}' excavated "
                                                        f"again (already in stage '{names[excavated[r]]}')"))
                excavated.setdefault(r, i)
        install = [s.install] if isinstance(s.install, str) else (s.install or [])
        for j, n in enumerate(install):
            key = here + ("install",) + ((j,) if not isinstance(s.install, str) else ())
            if n in structures:
                if n in installed:
                    out.append((key, f"expected '{n}' installed once, found it installed again"))
                installed.setdefault(n, i)
                continue
            if n not in linings:
                out.append((key, f"expected the name of a lining, wall, prop or anchor in construction "
                                 f"({', '.join(list(linings) + sorted(structures)) or 'none'}), found '{n}'"))
                continue
            if n in installed:
                out.append((key, f"expected lining '{n}' installed once, found it installed again"))
                continue
            ln = linings[n][1]
            need = expand(ln.on)
            missing = [r for r in need if r not in excavated]
            if missing:
                out.append((key, f"expected lining '{n}' installed at or after the excavation of '{ln.on}', found "
                                 f"'{missing[0]}' not yet excavated at stage '{s.name}'"))
            installed[n] = i
        for j, n in enumerate(s.remove or []):
            if n in structures:
                out.append((here + ("remove", j), f"expected a lining to remove, found '{n}' (removing walls, props "
                                                  f"and anchors is not modelled)"))
            elif n not in installed:
                out.append((here + ("remove", j), f"expected a lining installed in an earlier stage, found '{n}'"))
            elif n in removed:
                out.append((here + ("remove", j), f"expected lining '{n}' removed once, found it removed again"))
            else:
                removed[n] = i
        if s.release is not None and not (s.excavate or s.remove) and not open_groups:
            out.append((here + ("release",), f"expected a release for something excavated: stage '{s.name}' excavates "
                                             f"nothing and no earlier excavation is partly released"))
        if s.excavate or s.remove:
            open_groups = open_groups or s.release is not None
        elif s.release is None:
            open_groups = False
    if c.walls or c.props or c.anchors:
        from geoback.case.supports import support_problems

        out += support_problems(case, installed, excavated)
    for n, (j, ln) in linings.items():
        if n not in installed:
            out.append((at + ("linings", j), f"expected lining '{n}' installed by a stage, found no stage installing it"))
        for region in expand(ln.on):
            if region in excavated and n in installed and n not in removed:
                pass
    if not out:
        seq = Sequence.of(case)
        frac = seq.fractions(seq.values)
        for g in range(frac.shape[1]):
            col = frac[:, g]
            for k in range(1, len(col)):
                if col[k] < col[k - 1] - 1e-12:
                    out.append((at + ("stages", k, "release"),
                                f"expected releases that do not decrease (the load of stage '{names[seq.groups[g]]}' "
                                f"is {number_text(float(col[k - 1]))} released before), found {number_text(float(col[k]))}"))
    return out
