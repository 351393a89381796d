"""The ground's strength as data: which layers are Mohr-Coulomb, their named strength values and
the checks of a case's mohr-coulomb layers. No finite elements here (``plastic.py`` solves).

A layer with ``model: mohr-coulomb`` is elastic-perfectly plastic (Mohr-Coulomb yield surface, flow
potential of the same form with the dilation angle psi, optional tension cut-off; see
``plasticity/mohr_coulomb.py``). Its named values are ``c[layer]`` [kPa], ``phi[layer]`` and
``psi[layer]`` [degrees, as engineers write them; the return mapping works in radians] and, if the
case gives a cut-off, ``tension[layer]`` [kPa]. Linear-elastic layers of a case with some
mohr-coulomb layer are given a strength they never reach (``ELASTIC``).

In-situ stress (compression positive, vertical sv = gamma z, horizontal and out-of-plane K0 sv)
lies inside the Mohr-Coulomb surface iff, with s1 >= s3 the larger and smaller of sv and K0 sv,

    (s1 - s3) <= (s1 + s3) sin phi + 2 c cos phi,

that is  Ka - 2 c cos phi / (sv (1 + sin phi))  <=  K0  <=  Kp + 2 c cos phi / (sv (1 - sin phi)),
Ka = (1 - sin phi) / (1 + sin phi), Kp = 1 / Ka; linear in depth, so the layer's bottom decides.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

from geoback.case.schema import MC_FIELDS, Case, number_text
from geoback.case.limits import QUANTITIES, Limits

# a linear-elastic layer next to mohr-coulomb ones: a strength no stress reaches (c in kPa, angles in degrees)
ELASTIC = {"c": 1e30, "phi": 30.0, "psi": 30.0, "tension": math.inf}
# the load increments of an elastoplastic run (``plastic.py``): equal increments per unit of release,
# at least MIN_STAGE per stage; known from the case's releases before anything is meshed (``meshsize.py``)
INCREMENTS = 10
MIN_STAGE = 2


def stage_increments(steps, per_unit: int = INCREMENTS) -> list[int]:
    """Load increments of each stage releasing the fractions `steps` (beta_k - beta_(k-1))."""
    return [max(MIN_STAGE, int(math.ceil(per_unit * float(s) - 1e-9))) for s in steps]


def is_plastic(case: Case) -> bool:
    """Does any layer of the case yield (model: mohr-coulomb)?"""
    return any(layer.model == "mohr-coulomb" for layer in case.ground.layers)


@dataclass(frozen=True)
class Strength:
    """The named strength values of a case's mohr-coulomb layers."""

    layers: tuple[str, ...]  # every layer, in order
    plastic: tuple[bool, ...]  # which of them are mohr-coulomb
    values: dict  # c[layer], phi[layer], psi[layer], tension[layer] (cut-off only where given)

    @classmethod
    def of(cls, case: Case) -> "Strength":
        values = {}
        for layer in case.ground.layers:
            if layer.model != "mohr-coulomb":
                continue
            for f in MC_FIELDS:
                v = getattr(layer, f)
                if v is not None:
                    values[f"{f}[{layer.name}]"] = float(v)
        return cls(tuple(layer.name for layer in case.ground.layers),
                   tuple(layer.model == "mohr-coulomb" for layer in case.ground.layers), values)

    def knows(self, name: str) -> bool:
        return name in self.values

    def quantities(self) -> dict[str, float]:
        """The strength values of the case (c, phi, psi of every mohr-coulomb layer; tension where given)."""
        return dict(self.values)

    def canonical(self, name: str) -> str | None:
        """'c' -> 'c[clay]' when one layer is mohr-coulomb; None if not a strength value of the case."""
        base, _, rest = name.partition("[")
        if base not in MC_FIELDS:
            return None
        if not rest:
            named = [n for n in self.values if n.startswith(base + "[")]
            return named[0] if len(named) == 1 else None
        return name if name in self.values else None

    def unit(self, name: str) -> str | None:
        return QUANTITIES[name.partition("[")[0]][0] if name in self.values else None

    def limits(self, name: str, values: Mapping) -> Limits:
        """Allowed and usual range; the dilation angle at most the friction angle, the cut-off at
        most the apex c / tan phi of its layer."""
        base, _, rest = name.partition("[")
        layer, lim = rest[:-1], QUANTITIES[base][1]
        if base == "psi" and f"phi[{layer}]" in values:
            phi = float(values[f"phi[{layer}]"].real)
            return Limits(lim.lo, min(lim.hi, phi), (lim.plausible[0], min(lim.plausible[1], phi)))
        if base == "tension" and f"phi[{layer}]" in values and f"c[{layer}]" in values:
            apex = float(values[f"c[{layer}]"].real) / math.tan(math.radians(float(values[f"phi[{layer}]"].real)))
            return Limits(lim.lo, min(lim.hi, apex), (lim.plausible[0], min(lim.plausible[1], apex)))
        return lim

    def fields(self, values: Mapping, layer: str) -> tuple:
        """(c [kPa], phi [deg], psi [deg], tension [kPa]) of a layer at `values` (complex-safe)."""
        if not self.plastic[self.layers.index(layer)]:
            return tuple(ELASTIC[f] for f in MC_FIELDS)
        return tuple(values.get(f"{f}[{layer}]", ELASTIC["tension"] if f == "tension" else None) for f in MC_FIELDS)


# ---------------------------------------------------------------------------- checks of a case
def _k0_range(sv: float, c: float, phi_deg: float) -> tuple[float, float]:
    """K0 whose geostatic stress at vertical stress sv (> 0) the strength (c, phi) carries."""
    s = math.sin(math.radians(phi_deg))
    k = 2 * c * math.cos(math.radians(phi_deg)) / sv
    return (1 - s) / (1 + s) - k / (1 + s), (1 + s) / (1 - s) + k / (1 - s)


def strength_problems(case: Case) -> list[tuple[tuple, str]]:
    """Checks of the layers' models that pydantic cannot express: (path, message) for each."""
    out: list[tuple[tuple, str]] = []
    layers = case.ground.layers
    bottoms = [layer.top for layer in layers[1:]] + [case.geometry.depth]
    for i, layer in enumerate(layers):
        at = ("ground", "layers", i)
        if layer.model != "mohr-coulomb":
            for f in MC_FIELDS:
                if getattr(layer, f) is not None:
                    out.append((at + (f,), f"expected no '{f}' for a linear-elastic layer (give the layer "
                                           f"model: mohr-coulomb to make it yield), found {f} {number_text(getattr(layer, f))}"))
            continue
        missing = [f for f in ("c", "phi", "psi") if getattr(layer, f) is None]
        for f in missing:
            what = {"c": "the cohesion c [kPa] of a mohr-coulomb layer (e.g. c: 20 kPa; 0 for a cohesionless ground)",
                    "phi": "the friction angle phi [degrees] of a mohr-coulomb layer (e.g. phi: 30)",
                    "psi": "the dilation angle psi [degrees] of a mohr-coulomb layer (e.g. psi: 0 for no volume "
                           "change in shear; at most phi)"}[f]
            out.append((at + ("model",), f"expected {what}, found no '{f}' in layer '{layer.name}'"))
        if missing:
            continue
        if layer.psi > layer.phi:
            out.append((at + ("psi",), f"expected a dilation angle at most the friction angle phi = "
                                       f"{number_text(layer.phi)} degrees, found psi {number_text(layer.psi)}"))
        if layer.tension is not None and layer.tension > layer.c / math.tan(math.radians(layer.phi)) * (1 + 1e-12):
            apex = layer.c / math.tan(math.radians(layer.phi))
            out.append((at + ("tension",), f"expected a tension cut-off at most the Mohr-Coulomb apex c / tan(phi) "
                                           f"= {apex:.4g} kPa (beyond it the cut-off never acts), found "
                                           f"tension {number_text(layer.tension)} kPa"))
        k0 = layer.K0 if layer.K0 is not None else case.ground.K0
        if k0 is None:
            continue
        sv = case.ground.unit_weight * bottoms[i]
        if not sv > 0:  # a layer without thickness at the surface (refused with the layers' order)
            continue
        lo, hi = _k0_range(sv, layer.c, layer.phi)
        if not lo <= k0 <= hi:
            where = at + ("K0",) if layer.K0 is not None else ("ground", "K0")
            out.append((where, f"expected a K0 whose in-situ stress the strength of layer '{layer.name}' (c = "
                               f"{number_text(layer.c)} kPa, phi = {number_text(layer.phi)} degrees) can carry down to its bottom at "
                               f"{number_text(bottoms[i])} m, i.e. between {max(lo, 0):.3g} and {hi:.3g}, found K0 {number_text(k0)}"))
    if is_plastic(case):
        if case.mesh.order != 2:
            out.append((("mesh", "order"), "expected quadratic elements (order: 2) with a mohr-coulomb layer: linear "
                                           "triangles lock when plastic flow keeps the volume, found order 1"))
        if case.construction is not None and case.construction.lining is not None:
            out.append((("construction", "lining"), "expected no lining with mohr-coulomb ground: a lining on "
                                                    "yielding ground is not modelled (stages that release the "
                                                    "stress in steps are), found a lining"))
    return out
