"""The named physical values of a simulation, resolved in one place.

A case's values come from three statements of it: the construction plan (``beta[stage]``, the
lining's ``E[lining]``, ``nu[lining]``: ``case/construction.py``), the strength of mohr-coulomb
layers (``c[layer]``, ``phi[layer]``, ``psi[layer]``, ``tension[layer]``: ``case/strength.py``)
and the ground (``E[layer]``, ``nu[layer]``, ``K0``, ``K0[layer]`` and the extension table's
names: ``ground.py``). ``Names`` asks them in that order: a name the plan or the strength owns is
theirs (its unit and range from ``limits.QUANTITIES``, never an extension, so no null value), and
the ground answers the rest. A simulation holds the sources its physics honours (the one-step
model no plan, only the elastoplastic one a strength) and the stems it does not model.
"""
from __future__ import annotations

from typing import Mapping

from geoback.physics.ground import Ground


class Names:
    """Quantities, canonical names, units, ranges and null values over the plan, the strength and the
    ground (module docstring)."""

    def __init__(self, ground: Ground, plan=None, strength=None, unmodelled: tuple[str, ...] = ()):
        self.ground = ground
        self.sources = tuple(s for s in (plan, strength) if s is not None)  # case statements asked first
        self.unmodelled = tuple(unmodelled)

    def _owner(self, name: str):
        return next((s for s in self.sources if s.knows(name)), None)

    def quantities(self) -> dict[str, float]:
        """Every named physical value of the case, at the case's values."""
        out = dict(self.ground.baseline())
        for s in self.sources:
            out.update(s.quantities())
        return out

    def canonical(self, name: str) -> str | None:
        """Full name of a quantity ('E' -> 'E[clay]' for one layer, 'c' -> 'c[marl]'); None if unknown."""
        for s in self.sources:
            full = s.canonical(name)
            if full is not None:
                return full
        if name.partition("[")[0] in self.unmodelled:
            return None
        return self.ground.canonical(name)

    def unit(self, name: str) -> str:
        owner = self._owner(name)
        return owner.unit(name) if owner is not None else self.ground.unit(name)

    def limits(self, name: str, values: Mapping):
        """Allowed and usual range (``limits.Limits``), given the other values (a layer's nu, phi)."""
        owner = self._owner(name)
        return owner.limits(name, values) if owner is not None else self.ground.limits(name, values)

    def null_value(self, name: str, values: Mapping) -> float | None:
        """The value of an extension quantity that leaves the model at its baseline; None if not one."""
        if self._owner(name) is not None:
            return None
        return self.ground.null_value(name, values)
