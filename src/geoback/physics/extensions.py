"""The extension table: physics the baseline model may lack, each a named change of the ground's
fields (see ``geoback.physics.ground.Fields``). `geoback diagnose` proposes them as hypotheses; a case may
also identify them directly (``parameters: [{name: Egrad[clay], ...}]``) and `geoback simulate
--set` switches them on for study data. The simulation reads this table; nothing in the core
knows the individual rows.

| name           | null value       | unit  | what it changes                                             |
|----------------|------------------|-------|-------------------------------------------------------------|
| Egrad[layer]   | 0                | kPa/m | E = E_top + Egrad (depth - top) inside the layer            |
| Esplit[layer]  | E[layer]         | kPa   | E below depth zsplit[layer] inside the layer (a step added) |
| zsplit[layer]  | the layer bottom | m     | depth of that unmodelled boundary (fixed by search, not fit)|
| n[layer]       | 1                | -     | cross-anisotropy E_h / E_v                                  |
| m[layer]       | 1                | -     | G_vh / (E_v / (2 (1 + nu)))                                 |
| K0grad         | 0                | 1/m   | K0 = K0_axis + K0grad (depth - axis depth)                  |
| beta           | 1                | -     | fraction of the initial stress released                     |

Every ``apply`` is plain arithmetic on the fields, so complex values pass through and the
sensitivities stay exact (complex step, eqns 34-40).
"""
from __future__ import annotations

from geoback.case.layout import reference_depth

import numpy as np

from geoback.physics.ground import Extension
from geoback.case.limits import MODULUS, RELEASE, Limits


def _gradient(f, value, ground, i, values):
    sel = f.element_layer == i
    f.E[sel] = f.E[sel] + value * (f.element_depth[sel] - ground.tops[i])


def _split(f, value, ground, i, values):
    """E below zsplit: Esplit, as a step of Esplit - E[layer] on whatever else sets E there (a
    gradient), so that Esplit = E[layer] is the model without the boundary whatever the order."""
    z = values.get(f"zsplit[{ground.layers[i]}]")
    if z is None:
        return
    below = (f.element_layer == i) & (f.element_depth > np.real(z))
    f.E[below] = f.E[below] + (value - values[f"E[{ground.layers[i]}]"])


def _ratio(attr):
    def apply(f, value, ground, i, values):
        getattr(f, attr)[f.element_layer == i] = value
    return apply


def _k0_gradient(f, value, ground, i, values):
    f.k0 = f.k0 + value * (f.point_depth - reference_depth(ground.case))


def _release(f, value, ground, i, values):
    f.release = f.release * value


def _gradient_limits(values, ground, i) -> Limits:
    """E stays positive through the layer: Egrad > -E_top / thickness."""
    E = float(np.real(values[f"E[{ground.layers[i]}]"]))
    thick = float(ground.bottoms[i] - ground.tops[i])
    return Limits(-E / thick * (1 - 1e-6), 1e7, (-E / thick * 0.9, 1e4))


def _depth_limits(values, ground, i) -> Limits:
    return Limits(float(ground.tops[i]), float(ground.bottoms[i]), (float(ground.tops[i]), float(ground.bottoms[i])))


def _anisotropy_limits(values, ground, i) -> Limits:
    """Cross-anisotropic stiffness positive definite (with G_vh from E_v): n < (1 - nu) / (2 nu^2)."""
    nu = float(np.real(values[f"nu[{ground.layers[i]}]"]))
    top = (1 - nu) / (2 * nu * nu) if nu > 0 else 1e3
    return Limits(1e-2, min(top * (1 - 1e-6), 1e3), (0.3, min(3.0, top)))


EXTENSIONS: dict[str, Extension] = {e.base: e for e in (
    Extension("Egrad", True, "kPa/m", 0.0, _gradient, "modulus increasing linearly with depth",
              limits=_gradient_limits),
    Extension("Esplit", True, "kPa", lambda values, layer: values[f"E[{layer}]"], _split,
              "another modulus below depth zsplit inside the layer", limits=MODULUS),
    Extension("zsplit", True, "m", lambda values, layer: np.inf, None,
              "depth of an unmodelled layer boundary", identifiable=False, limits=_depth_limits),
    Extension("n", True, "-", 1.0, _ratio("n"), "cross-anisotropy E_h / E_v", limits=_anisotropy_limits),
    Extension("m", True, "-", 1.0, _ratio("m"), "shear modulus G_vh relative to isotropy",
              limits=Limits(1e-2, 1e2, (0.3, 3.0))),
    Extension("K0grad", False, "1/m", 0.0, _k0_gradient, "K0 changing linearly with depth",
              limits=Limits(-1.0, 1.0, (-0.1, 0.1))),
    Extension("beta", False, "-", 1.0, _release, "fraction of the initial stress released",
              limits=RELEASE),
)}
