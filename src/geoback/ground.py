"""The ground as a function of named physical values: element stiffness coefficients and the
initial stress released on the tunnel wall.

Values are named ``E[layer]``, ``nu[layer]``, ``K0`` (ground-wide) or ``K0[layer]``;
model extensions add their own names (see ``EXTENSIONS``). ``state()`` is written with plain
numpy arithmetic so that it also accepts complex values: ``derivatives()`` differentiates it
by complex step, exact to rounding, which together with eqns (34)-(40) gives exact FEM
sensitivities without finite differences.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .case import Case

# Extensions of the baseline model (all zero / neutral by default), used by `diagnose`:
#   Egrad[layer]  modulus increase with depth below the layer's top [kPa/m]
#   K0grad        change of K0 per metre of depth below the tunnel axis [1/m]
#   beta          fraction of the initial stress released by the excavation [-]
#   n[layer]      cross-anisotropy E_h / E_v [-];  m[layer]: G_vh / (E_v / (2 (1 + nu))) [-]
#   Esplit[layer] modulus below depth zsplit[layer] inside the layer (an unmodelled boundary) [kPa]
EXTENSIONS = {"Egrad": 0.0, "K0grad": 0.0, "beta": 1.0, "n": 1.0, "m": 1.0}


def plane_strain_isotropic(E, nu):
    """Entries (D11, D22, D12, D33) of the plane-strain D of eqn (32)/(37a)."""
    f = E / ((1 + nu) * (1 - 2 * nu))
    return f * (1 - nu), f * (1 - nu), f * nu, E / (2 * (1 + nu))


def plane_strain_cross_anisotropic(Ev, nu_vh, n, m, nu_hh):
    """Plane strain (x horizontal, y vertical axis of symmetry), E_h = n E_v, G_vh = m G_iso.

    Compliance (x, y, z=out of plane, horizontal): condensed with eps_zz = 0.
    With n = m = 1 and nu_hh = nu_vh it equals the isotropic D.
    """
    Eh = n * Ev
    # 3D compliance entries for normal strains (x, y, z)
    sxx, syy, szz = 1 / Eh, 1 / Ev, 1 / Eh
    sxy = -nu_vh / Ev          # eps_x from sigma_y
    sxz = -nu_hh / Eh          # eps_x from sigma_z
    syz = -nu_vh / Ev          # eps_y from sigma_z
    # plane strain: eps_z = 0 -> sigma_z = -(sxz sx + syz sy)/szz
    a11 = sxx - sxz * sxz / szz
    a22 = syy - syz * syz / szz
    a12 = sxy - sxz * syz / szz
    det = a11 * a22 - a12 * a12
    G = m * Ev / (2 * (1 + nu_vh))
    return a22 / det, a11 / det, -a12 / det, G


@dataclass
class GroundState:
    coeffs: np.ndarray  # (ne, 4) D11, D22, D12, D33 per element
    sigma_v: np.ndarray  # (nq,) beta * vertical stress at the wall points (compression negative)
    sigma_h: np.ndarray  # (nq,) beta * K0 * vertical stress at the wall points


class Ground:
    """Maps named values to the FE model's inputs for one mesh."""

    def __init__(self, case: Case, element_depth: np.ndarray, element_region: np.ndarray,
                 wall_depth: np.ndarray):
        self.case = case
        self.layers = [layer.name for layer in case.ground.layers]
        self.tops = np.array([layer.top for layer in case.ground.layers])
        self.element_depth = element_depth
        self.element_region = element_region
        self.wall_depth = wall_depth
        self.wall_region = np.searchsorted(self.tops, wall_depth, side="right") - 1

    def baseline(self) -> dict[str, float]:
        """The case's values of every baseline quantity."""
        g = self.case.ground
        values: dict[str, float] = {}
        for layer in g.layers:
            values[f"E[{layer.name}]"] = layer.E
            values[f"nu[{layer.name}]"] = layer.nu
            if layer.K0 is not None:
                values[f"K0[{layer.name}]"] = layer.K0
        if g.K0 is not None:
            values["K0"] = g.K0
        return values

    def canonical(self, name: str) -> str | None:
        """Full name of a quantity ('E' -> 'E[clay]' for a single layer); None if unknown."""
        base, _, rest = name.partition("[")
        layer = rest.rstrip("]") if rest else None
        per_layer = {"E", "nu", "Egrad", "n", "m", "Esplit", "zsplit"}
        if base in per_layer:
            if layer is None:
                if len(self.layers) != 1:
                    return None
                layer = self.layers[0]
            return f"{base}[{layer}]" if layer in self.layers else None
        if base == "K0":
            if layer is None:
                return "K0" if self.case.ground.K0 is not None or len(self.layers) == 1 else None
            return f"K0[{layer}]" if layer in self.layers else None
        if base in ("K0grad", "beta") and layer is None:
            return base
        return None

    def _layer_k0(self, values: dict, i: int):
        name = self.layers[i]
        if f"K0[{name}]" in values:
            return values[f"K0[{name}]"]
        return values["K0"]

    def state(self, values: dict) -> GroundState:
        """Element coefficients and released wall stresses (eqns 32, 39-40); complex-safe."""
        dtype = complex if any(isinstance(v, complex) for v in values.values()) else float
        ne = len(self.element_depth)
        coeffs = np.zeros((ne, 4), dtype=dtype)
        for i, name in enumerate(self.layers):
            sel = self.element_region == i
            E = values[f"E[{name}]"] + values.get(f"Egrad[{name}]", 0.0) * (self.element_depth[sel] - self.tops[i])
            if f"zsplit[{name}]" in values:
                below = self.element_depth[sel] > values[f"zsplit[{name}]"]
                E = np.where(below, values.get(f"Esplit[{name}]", values[f"E[{name}]"]), E)
            nu = values[f"nu[{name}]"]
            n, m = values.get(f"n[{name}]", 1.0), values.get(f"m[{name}]", 1.0)
            if n == 1.0 and m == 1.0 and not isinstance(n, complex) and not isinstance(m, complex):
                d = plane_strain_isotropic(E, nu)
            else:
                d = plane_strain_cross_anisotropic(E, nu, n, m, nu)
            for c in range(4):
                coeffs[sel, c] = d[c]
        gamma = self.case.ground.unit_weight
        beta = values.get("beta", 1.0)
        sv = -gamma * self.wall_depth * beta
        k0 = np.zeros(len(self.wall_depth), dtype=dtype)
        for i in range(len(self.layers)):
            k0[self.wall_region == i] = self._layer_k0(values, i)
        k0 = k0 + values.get("K0grad", 0.0) * (self.wall_depth - self.case.geometry.axis_depth)
        return GroundState(coeffs, np.asarray(sv, dtype=dtype), k0 * sv)

    def derivatives(self, values: dict, names: list[str]) -> list[GroundState]:
        """d state / d value for each name, by complex step (exact for this analytic map)."""
        out = []
        for name in names:
            v = dict(values)
            h = 1e-30 * max(1.0, abs(values[name]))
            v[name] = values[name] + 1j * h
            s = self.state(v)
            out.append(GroundState(s.coeffs.imag / h, s.sigma_v.imag / h, s.sigma_h.imag / h))
        return out
