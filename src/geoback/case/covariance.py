"""Measurement covariance matrices of linewise instruments.

Ledesma, Gens & Alonso (1996), Part I, section "Measurement covariance matrix"
(eqns 10-26): sliding micrometer (extensometer), inclinometer and deflectometer.

Conventions
-----------
* Stations are numbered 1..n from the instrument's reference end.
* ``lengths`` l_1..l_n are the lengths between consecutive measuring points,
  starting at the reference end; station i lies at L_i = l_1 + ... + l_i.
* Displacements are the primary readings (strain increments eps_i, slopes
  alpha_i or curvatures kappa_i) integrated from the reference end; the
  integration constants (A; B; C, D) enter only through ``constant_matrix``
  and through their variances.

The closed forms (eqns 12-20) are implemented as independent vectorised
formulas so that they can be checked against ``sigma^2 W W^t + G diag(var) G^t``
(eqn 26).  The deflectometer uses the ERRATA-corrected eqns 18-20
(see docs/architecture.md): the printed inner sums are wrong.

Pure numpy (and geoback's error classes).
"""

from __future__ import annotations

import json
import math
import numbers
from collections.abc import Mapping, Sequence

import numpy as np

from geoback.errors import GeobackError

__all__ = [
    "KINDS",
    "NotPositiveDefinite",
    "normalise_kind",
    "station_lengths",
    "integration_matrix",
    "constant_matrix",
    "constant_names",
    "sliding_micrometer_covariance",
    "inclinometer_covariance",
    "deflectometer_covariance",
    "instrument_covariance",
    "structure_matrix",
    "cholesky_factor",
    "render_matrix",
]

KINDS = ("sliding_micrometer", "inclinometer", "deflectometer")

_ALIASES = {
    "sliding_micrometer": "sliding_micrometer",
    "sliding_micrometre": "sliding_micrometer",
    "extensometer": "sliding_micrometer",
    "inclinometer": "inclinometer",
    "deflectometer": "deflectometer",
}

_CONSTANTS = {
    "sliding_micrometer": ("A",),
    "inclinometer": ("B",),
    "deflectometer": ("C", "D"),
}


class NotPositiveDefinite(GeobackError, ValueError):
    """A covariance matrix is not symmetric positive definite."""


# ---------------------------------------------------------------------------
# input handling
# ---------------------------------------------------------------------------


def normalise_kind(kind: str) -> str:
    """Canonical instrument kind (one of ``KINDS``).

    Case-insensitive; hyphens and spaces are treated as underscores;
    ``"extensometer"`` is an alias of ``"sliding_micrometer"``.
    """
    if not isinstance(kind, str):
        raise ValueError(f"instrument kind must be a string, got {kind!r}")
    key = kind.strip().lower().replace("-", "_").replace(" ", "_")
    try:
        return _ALIASES[key]
    except KeyError:
        raise ValueError(
            f"unknown instrument kind {kind!r}; expected one of "
            f"{', '.join(KINDS)} (or 'extensometer' for sliding_micrometer)"
        ) from None


def _check_lengths(lengths) -> np.ndarray:
    arr = np.asarray(lengths, dtype=float)
    if arr.ndim != 1:
        raise ValueError(f"lengths must be a 1-D sequence, got shape {arr.shape}")
    if arr.size == 0:
        raise ValueError("lengths must contain at least one station")
    if not np.all(np.isfinite(arr)):
        raise ValueError("lengths must be finite")
    bad = np.flatnonzero(arr <= 0)
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"lengths must all be > 0; l_{i + 1} (station {i + 1}) = {arr[i]!r}"
        )
    return arr.copy()


def station_lengths(
    stations: int | None = None,
    spacing: float | None = None,
    lengths: Sequence[float] | None = None,
) -> np.ndarray:
    """Lengths l_1..l_n between consecutive measuring points.

    Either ``lengths`` (all > 0; ``stations``, if also given, must equal their
    number) or ``stations`` N >= 1 with a uniform ``spacing`` > 0.
    """
    if lengths is not None:
        if spacing is not None:
            raise ValueError(
                "give either explicit lengths or stations with a spacing, not "
                "both lengths and spacing"
            )
        arr = _check_lengths(lengths)
        if stations is not None:
            n = _check_stations(stations)
            if n != arr.size:
                raise ValueError(
                    f"stations = {n} but {arr.size} lengths were given; "
                    "there must be one length per station"
                )
        return arr
    if stations is None or spacing is None:
        raise ValueError(
            "station lengths need either `lengths`, or both `stations` and "
            "`spacing`"
        )
    n = _check_stations(stations)
    if isinstance(spacing, bool) or not isinstance(spacing, numbers.Real):
        raise ValueError(f"spacing must be a number, got {spacing!r}")
    s = float(spacing)
    if not math.isfinite(s) or s <= 0:
        raise ValueError(f"spacing must be finite and > 0, got {spacing!r}")
    return np.full(n, s)


def _check_stations(stations) -> int:
    if isinstance(stations, bool) or not isinstance(stations, numbers.Integral):
        raise ValueError(f"stations must be an integer, got {stations!r}")
    n = int(stations)
    if n < 1:
        raise ValueError(f"stations must be >= 1, got {n}")
    return n


def _check_sigma(sigma) -> float:
    s = float(sigma)
    if not math.isfinite(s) or s <= 0:
        raise ValueError(f"sigma must be finite and > 0, got {sigma!r}")
    return s


def _check_var(value, name: str) -> float:
    v = float(value)
    if not math.isfinite(v) or v < 0:
        raise ValueError(f"variance of constant {name} must be finite and >= 0, got {value!r}")
    return v


# ---------------------------------------------------------------------------
# linear maps: primary readings / constants -> displacements
# ---------------------------------------------------------------------------


def integration_matrix(kind: str, lengths) -> np.ndarray:
    """W (n x n) with displacements = W @ primary readings (constants zero).

    * sliding micrometer, eqn 11: v_n = sum_{i<=n} eps_i           -> W_ni = 1
    * inclinometer, eqns 15/22:   u_n = sum_{i<=n} alpha_i l_i     -> W_ni = l_i
    * deflectometer, eqn 18 (ERRATA-corrected):
      u_n = sum_{i<=n} kappa_i l_i (sum_{k=i}^n l_k) -> W_ni = l_i (L_n - L_{i-1})

    for i <= n, and W_ni = 0 for i > n.
    """
    kind = normalise_kind(kind)
    l = _check_lengths(lengths)
    n = l.size
    lower = np.tri(n, dtype=bool)  # lower[r, c] = c <= r
    if kind == "sliding_micrometer":
        return lower.astype(float)
    if kind == "inclinometer":
        return np.where(lower, l[None, :], 0.0)
    L = np.cumsum(l)
    L_prev = L - l  # L_{i-1}
    return np.where(lower, l[None, :] * (L[:, None] - L_prev[None, :]), 0.0)


def constant_matrix(kind: str, lengths) -> np.ndarray:
    """G (n x k) with displacements from integration constants = G @ constants.

    Sliding micrometer: A (eqn 11) -> ones; inclinometer: B (eqn 15) -> ones;
    deflectometer: C, D (eqn 18) -> columns [L_n, 1].
    """
    kind = normalise_kind(kind)
    l = _check_lengths(lengths)
    ones = np.ones((l.size, 1))
    if kind == "deflectometer":
        return np.column_stack([np.cumsum(l), np.ones(l.size)])
    return ones


def constant_names(kind: str) -> tuple[str, ...]:
    """Names of the integration constants: ("A",), ("B",) or ("C", "D")."""
    return _CONSTANTS[normalise_kind(kind)]


# ---------------------------------------------------------------------------
# closed forms
# ---------------------------------------------------------------------------


def sliding_micrometer_covariance(n: int, sigma: float, var_a: float = 0.0) -> np.ndarray:
    """C_ij = sigma^2 min(i, j) + var A  (eqns 12-14)."""
    n = _check_stations(n)
    s = _check_sigma(sigma)
    va = _check_var(var_a, "A")
    idx = np.arange(1, n + 1, dtype=float)
    return s**2 * np.minimum.outer(idx, idx) + va


def inclinometer_covariance(lengths, sigma: float, var_b: float = 0.0) -> np.ndarray:
    """C_ij = sigma^2 sum_{m<=min(i,j)} l_m^2 + var B  (eqns 16-17)."""
    l = _check_lengths(lengths)
    s = _check_sigma(sigma)
    vb = _check_var(var_b, "B")
    S0 = np.cumsum(l**2)
    k = np.minimum.outer(np.arange(l.size), np.arange(l.size))
    return s**2 * S0[k] + vb


def deflectometer_covariance(
    lengths, sigma: float, var_c: float = 0.0, var_d: float = 0.0
) -> np.ndarray:
    """Deflectometer covariance, eqns 19-20 as corrected in the ERRATA.

    C_ij = sigma^2 sum_{m<=min(i,j)} l_m^2 (sum_{r=m}^i l_r)(sum_{s=m}^j l_s)
           + L_i L_j var C + var D.

    (The paper prints the inner sum as sum_{s=n}^j; it must be sum_{s=m}^j.)
    Evaluated with prefix sums of positive terms only: for k = min(i, j),
    E_ij = Q_k + |L_j - L_i| T_k with T_k = sum_{m<=k} l_m^2 (L_k - L_{m-1}),
    Q_k = sum_{m<=k} l_m^2 (L_k - L_{m-1})^2, using the recurrences
    T_k = T_{k-1} + l_k S_k and Q_k = Q_{k-1} + 2 l_k T_{k-1} + l_k^2 S_k,
    S_k = sum_{m<=k} l_m^2.
    """
    l = _check_lengths(lengths)
    s = _check_sigma(sigma)
    vc = _check_var(var_c, "C")
    vd = _check_var(var_d, "D")
    L = np.cumsum(l)
    S = np.cumsum(l**2)
    T = np.cumsum(l * S)
    T_prev = np.concatenate(([0.0], T[:-1]))
    Q = np.cumsum(2.0 * l * T_prev + l**2 * S)
    n = l.size
    k = np.minimum.outer(np.arange(n), np.arange(n))
    E = Q[k] + np.abs(L[:, None] - L[None, :]) * T[k]
    return s**2 * E + vc * np.outer(L, L) + vd


def _variances_for(kind: str, variances: Mapping[str, float] | None) -> dict[str, float]:
    names = _CONSTANTS[kind]
    out = {name: 0.0 for name in names}
    if variances is None:
        return out
    unknown = sorted(set(variances) - set(names))
    if unknown:
        raise ValueError(
            f"{kind} has integration constant(s) {', '.join(names)}; "
            f"unexpected variance key(s): {', '.join(map(repr, unknown))}"
        )
    for name, value in variances.items():
        out[name] = _check_var(value, name)
    return out


def instrument_covariance(
    kind: str,
    lengths,
    sigma: float,
    variances: Mapping[str, float] | None = None,
) -> np.ndarray:
    """C_x = sigma^2 E_x (eqn 10) for a linewise instrument.

    ``variances`` maps integration-constant name (see ``constant_names``) to
    its variance; missing constants have variance 0 (exactly known).
    """
    kind = normalise_kind(kind)
    l = _check_lengths(lengths)
    v = _variances_for(kind, variances)
    if kind == "sliding_micrometer":
        return sliding_micrometer_covariance(l.size, sigma, v["A"])
    if kind == "inclinometer":
        return inclinometer_covariance(l, sigma, v["B"])
    return deflectometer_covariance(l, sigma, v["C"], v["D"])


def structure_matrix(
    kind: str,
    lengths,
    sigma: float,
    variances: Mapping[str, float] | None = None,
) -> np.ndarray:
    """Error structure E_x = C_x / sigma^2 (eqn 10; eqns 13-14, 17, 20)."""
    s = _check_sigma(sigma)
    return instrument_covariance(kind, lengths, s, variances) / s**2


# ---------------------------------------------------------------------------
# factorisation and output
# ---------------------------------------------------------------------------


def cholesky_factor(C, name: str = "") -> np.ndarray:
    """Lower Cholesky factor L with C = L L^t.

    Raises ``NotPositiveDefinite`` (a ValueError) naming ``name`` and giving the
    smallest eigenvalue if C is not symmetric positive definite.
    """
    A = np.asarray(C, dtype=float)
    label = f"covariance matrix of {name!r}" if name else "covariance matrix"
    if A.ndim != 2 or A.shape[0] != A.shape[1] or A.shape[0] == 0:
        raise NotPositiveDefinite(f"{label} must be a non-empty square matrix, got shape {A.shape}")
    if not np.all(np.isfinite(A)):
        raise NotPositiveDefinite(f"{label} contains non-finite entries")
    scale = max(float(np.max(np.abs(A))), np.finfo(float).tiny)
    asym = float(np.max(np.abs(A - A.T)))
    if asym > 1e-12 * scale:
        raise NotPositiveDefinite(
            f"{label} is not symmetric (max |C - C^t| = {asym:.3g})"
        )
    try:
        return np.linalg.cholesky(A)
    except np.linalg.LinAlgError:
        lam = float(np.linalg.eigvalsh(0.5 * (A + A.T))[0])
        raise NotPositiveDefinite(
            f"{label} is not positive definite (smallest eigenvalue {lam:.6g})"
        ) from None


def render_matrix(
    C,
    fmt: str = "table",
    header: bool = True,
    labels: Sequence[str] | None = None,
) -> str:
    """Render a square matrix as "csv", "json" or a plain-text "table".

    * csv: one row per line, comma separated, each entry ``repr(float)`` (the
      shortest string that parses back to the same double); with ``header``
      one first row of labels.
    * json: ``{"labels": [...], "matrix": [[...]]}`` (exact doubles; labels
      always included).
    * table: aligned text with row and column labels (omitted if not
      ``header``).

    Labels default to s1..sn.
    """
    A = np.asarray(C, dtype=float)
    if A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise ValueError(f"render_matrix needs a square matrix, got shape {A.shape}")
    n = A.shape[0]
    if labels is None:
        labs = [f"s{i + 1}" for i in range(n)]
    else:
        labs = [str(x) for x in labels]
        if len(labs) != n:
            raise ValueError(f"{len(labs)} labels given for a {n} x {n} matrix")
    rows = [[float(x) for x in row] for row in A]
    fmt_key = str(fmt).lower()
    if fmt_key == "csv":
        lines = []
        if header:
            lines.append(",".join(labs))
        lines.extend(",".join(repr(x) for x in row) for row in rows)
        return "\n".join(lines) + "\n"
    if fmt_key == "json":
        return json.dumps({"labels": labs, "matrix": rows}, allow_nan=False)
    if fmt_key == "table":
        cells = [[f"{x:.6g}" for x in row] for row in rows]
        width = max([len(c) for row in cells for c in row] + ([len(x) for x in labs] if header else [1]))
        lines = []
        if header:
            lab_w = max(len(x) for x in labs)
            lines.append(" " * lab_w + "  " + "  ".join(x.rjust(width) for x in labs))
            for lab, row in zip(labs, cells):
                lines.append(lab.ljust(lab_w) + "  " + "  ".join(c.rjust(width) for c in row))
        else:
            for row in cells:
                lines.append("  ".join(c.rjust(width) for c in row))
        return "\n".join(lines) + "\n"
    raise ValueError(f"unknown matrix format {fmt!r}; expected 'table', 'csv' or 'json'")
