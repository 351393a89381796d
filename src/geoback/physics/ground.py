"""The ground as a function of named physical values: element stiffness coefficients and the
initial stress released on the tunnel wall (eqns 32, 37, 39-40).

Values are named ``E[layer]``, ``nu[layer]``, ``K0`` (ground-wide) or ``K0[layer]``. The map goes
through *fields*: E, nu, the anisotropy ratios n, m per element, K0 at the wall points and the
fraction of the initial stress released. Model extensions (``Extension``, declared in a table the
caller passes in: `geoback diagnose` owns it) change these fields, so a new extension is one row
of that table and nothing here.

Everything is plain numpy arithmetic that also accepts complex values: ``derivatives()``
differentiates the map by complex step, exact to rounding, which with eqns (34)-(40) gives exact
FEM sensitivities without finite differences.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from geoback.case.loading import Case
from geoback.case.limits import QUANTITIES, Limits

COMPLEX_STEP = 1e-30
STEMS = ("E", "nu", "K0")  # the ground's own quantities (units and ranges: limits.QUANTITIES)


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
class Fields:
    """What the stiffness and the load are made of: per element E, nu, n (E_h/E_v), m (G_vh ratio);
    per stress point (the wall's quadrature points unless asked otherwise) K0; the fraction of the
    initial stress released. The depths and layers they are defined at come along (read-only)."""

    E: np.ndarray
    nu: np.ndarray
    n: np.ndarray
    m: np.ndarray
    k0: np.ndarray
    release: complex | float
    element_depth: np.ndarray
    element_layer: np.ndarray
    point_depth: np.ndarray
    point_layer: np.ndarray


@dataclass(frozen=True)
class Extension:
    """A named change of the baseline model (a row of an extension table).

    base: the name's stem ('Egrad'); per_layer: named 'base[layer]'; null: the value at which the
    model equals the baseline (a number, or a function of (values, layer) such as 'the layer's E');
    apply(fields, value, ground, layer_index, values) changes the fields in place (complex-safe);
    identifiable: False for companions fixed by search, not by the fit (a boundary's depth)."""

    base: str
    per_layer: bool
    unit: str
    null: float | Callable[[Mapping, str], float]
    apply: Callable[["Fields", object, "Ground", int | None, Mapping], None] | None = None
    description: str = ""
    identifiable: bool = True
    limits: Limits | Callable[[Mapping, "Ground", int | None], Limits] = Limits(-1e9, 1e9, (-1e9, 1e9))


@dataclass
class GroundState:
    coeffs: np.ndarray  # (ne, 4) D11, D22, D12, D33 per element
    sigma_v: np.ndarray  # (nq,) released vertical stress at the wall points (compression negative)
    sigma_h: np.ndarray  # (nq,) released horizontal stress at the wall points


@dataclass
class Ground:
    """Maps named values to the FE model's inputs for one mesh (element depths and layers, wall
    point depths), with the extensions of `extensions` available by name."""

    case: Case
    element_depth: np.ndarray
    element_region: np.ndarray
    wall_depth: np.ndarray
    extensions: Mapping[str, Extension] = field(default_factory=dict)

    def __post_init__(self):
        self.layers = [layer.name for layer in self.case.ground.layers]
        self.tops = np.array([layer.top for layer in self.case.ground.layers])
        self.bottoms = np.append(self.tops[1:], self.case.geometry.depth)
        self.wall_region = np.searchsorted(self.tops, self.wall_depth, side="right") - 1
        self._in_layer = [self.element_region == i for i in range(len(self.layers))]

    # ------------------------------------------------------------------ names
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
        layer = rest[:-1] if rest.endswith("]") else (None if not rest else "\0")
        ext = self.extensions.get(base)
        if base in ("E", "nu") or (ext is not None and ext.per_layer):
            if layer is None:
                if len(self.layers) != 1:
                    return None
                layer = self.layers[0]
            return f"{base}[{layer}]" if layer in self.layers else None
        if base == "K0":
            if layer is None:
                return "K0" if self.case.ground.K0 is not None or len(self.layers) == 1 else None
            return f"K0[{layer}]" if layer in self.layers else None
        if ext is not None and layer is None:
            return base
        return None

    def null_value(self, name: str, values: Mapping) -> float | None:
        """The value of an extension quantity that leaves the model at its baseline."""
        base, _, rest = name.partition("[")
        ext = self.extensions.get(base)
        if ext is None:
            return None
        return float(ext.null(values, rest.rstrip("]"))) if callable(ext.null) else float(ext.null)

    def unit(self, name: str) -> str:
        base = name.split("[")[0]
        if base in self.extensions:
            return self.extensions[base].unit
        return QUANTITIES[base][0] if base in STEMS else "-"

    def limits(self, name: str, values: Mapping) -> Limits:
        """Allowed and usual range of a quantity (given the other values, e.g. a layer's nu)."""
        base, _, rest = name.partition("[")
        if base in STEMS:
            return QUANTITIES[base][1]
        ext = self.extensions[base]
        if callable(ext.limits):
            layer = self.layers.index(rest[:-1]) if ext.per_layer else None
            return ext.limits(values, self, layer)
        return ext.limits

    # ------------------------------------------------------------------ the map
    def layer_k0(self, values: Mapping, i: int):
        name = self.layers[i]
        return values.get(f"K0[{name}]", values.get("K0"))

    def fields(self, values: Mapping, point_depth: np.ndarray | None = None,
               point_layer: np.ndarray | None = None) -> Fields:
        """Baseline fields from the named values, then every extension named in `values`.
        K0 is sampled at the wall points, or at `point_depth` (layers `point_layer`) if given."""
        dtype = complex if any(isinstance(v, complex) for v in values.values()) else float
        ne = len(self.element_depth)
        E = np.empty(ne, dtype)
        nu = np.empty(ne, dtype)
        for i, name in enumerate(self.layers):
            E[self._in_layer[i]] = values[f"E[{name}]"]
            nu[self._in_layer[i]] = values[f"nu[{name}]"]
        if point_depth is None:
            point_depth, point_layer = self.wall_depth, self.wall_region
        k0 = np.empty(len(point_depth), dtype)
        for i in range(len(self.layers)):
            k0[point_layer == i] = self.layer_k0(values, i)
        f = Fields(E, nu, np.ones(ne, dtype), np.ones(ne, dtype), k0, 1.0, self.element_depth,
                   self.element_region, point_depth, point_layer)
        for name, value in values.items():
            base, _, rest = name.partition("[")
            ext = self.extensions.get(base)
            if ext is None or ext.apply is None:
                continue
            layer = self.layers.index(rest[:-1]) if ext.per_layer else None
            ext.apply(f, value, self, layer, values)
        return f

    def state(self, values: Mapping) -> GroundState:
        """Element coefficients and released wall stresses (eqns 32, 39-40); complex-safe."""
        if not any(name.partition("[")[0] in self.extensions for name in values):
            return self._layered_state(values)
        f = self.fields(values)
        if np.all(f.n == 1.0) and np.all(f.m == 1.0):  # exactly isotropic (no perturbation either)
            d = plane_strain_isotropic(f.E, f.nu)
        else:
            d = plane_strain_cross_anisotropic(f.E, f.nu, f.n, f.m, f.nu)
        coeffs = np.column_stack(d)
        sv = -self.case.ground.unit_weight * self.wall_depth * f.release
        return GroundState(coeffs, np.asarray(sv, dtype=coeffs.dtype), f.k0 * sv)

    def _layered_state(self, values: Mapping) -> GroundState:
        """state() of layer-wise constant isotropic ground (no extension): D of each layer, spread
        over its elements, the same numbers as the general path computes element by element."""
        dtype = complex if any(isinstance(v, complex) for v in values.values()) else float
        table = np.array([plane_strain_isotropic(values[f"E[{n}]"], values[f"nu[{n}]"]) for n in self.layers],
                         dtype=dtype).reshape(len(self.layers), 4)
        k0 = np.array([self.layer_k0(values, i) for i in range(len(self.layers))], dtype=dtype)
        sv = -self.case.ground.unit_weight * self.wall_depth
        return GroundState(table[self.element_region], sv.astype(dtype), k0[self.wall_region] * sv)

    def derivatives(self, values: Mapping, names: list[str]) -> list[GroundState]:
        """d state / d value for each name, by complex step (exact for this analytic map)."""
        out = []
        for name in names:
            v = dict(values)
            h = COMPLEX_STEP * max(1.0, abs(values[name]))
            v[name] = values[name] + 1j * h
            s = self.state(v)
            out.append(GroundState(s.coeffs.imag / h, s.sigma_v.imag / h, s.sigma_h.imag / h))
        return out

    def initial_stress(self, values: Mapping, depth: np.ndarray, region: np.ndarray) -> np.ndarray:
        """Geostatic (sxx, syy, sxy) at points of the given depths and layers (compression negative),
        with the K0 of each layer (extensions that change K0 with depth included)."""
        sv = -self.case.ground.unit_weight * np.asarray(depth, float)
        k0 = self.fields(values, np.asarray(depth, float), np.asarray(region)).k0.real
        return np.column_stack([k0 * sv, sv, np.zeros_like(sv)])
