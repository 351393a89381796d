"""Linear analysis about an estimate: the parameters' posterior covariance (eqn 55), the variance of
predictions made with them, and the posterior a candidate instrument's readings would give (data
worth). The one place where eqn 55 is solved; modelled on pyEMU's ``Schur`` (posterior_parameter,
posterior_prediction, get_conditional_instance), for the whitened problem of ERRATA.md.

With C_x = L L^t, the whitened sensitivity A' = L^-1 A (the readings' rows) and the prior's rows
C_p0^-1/2 (parameters with a prior), stacked into G = [A'; C_p0^-1/2],

    C_p = (A'^t A' + C_p0^-1)^-1 = (G^t G)^-1                                     (eqn 55)

Parameters span many decades (moduli in kPa beside ratios), so the problem is equilibrated once:
z = p / d, G_d = G diag(d) (d: |p| for relative changes dp/p as the reliability measures use it, or
the Jacobi scaling 1 / sqrt(diag I) of an information matrix I), and factorised by the SVD
G_d = U S V^t (or, given only I, the eigen-decomposition of diag(d) I diag(d) = V S^2 V^t). A
direction v_k with s_k <= rtol s_1 (rtol = ILL_CONDITIONED = 1e-8 for rows; sqrt(EIGEN_RTOL) for an
information matrix, whose small eigenvalues carry an error of about n eps s_1^2) is not
determined by the readings and priors:

    C_p = diag(d) V_+ S_+^-2 V_+^t diag(d)        (sum over the determined directions only)

and the standard deviation of every parameter with a component above 0.05 on an undetermined
direction is infinite (its variance is unbounded), as is a prediction's that reaches one.

Prediction variance (first-order, FOSM; eqn 55 propagated): for predictions q = g^t p with
sensitivities G_q = dq/dp (rows g^t), C_q = G_q C_p G_q^t, var q_i = g_i^t C_p g_i.

Data worth: a candidate instrument c with whitened sensitivity rows A_c' = L_c^-1 A_c adds its
rows to G, so that after it C_p,c = (G^t G + A_c'^t A_c')^-1 (eqn 55 with the candidate's readings,
``conditional``), on the same equilibration.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from geoback.inference.frozen import readonly

ILL_CONDITIONED = 1e-8  # smallest / largest singular value below which a combination is undetermined
EIGEN_RTOL = 1e-15  # from an information matrix: smallest / largest eigenvalue resolved (numpy's pinv)
INVOLVED = 0.05  # a parameter (prediction) with a larger component on an undetermined direction is unbounded


@dataclass(frozen=True, eq=False)
class LinearAnalysis:
    """The posterior of the parameters about an estimate (eqn 55), factorised once (module docstring).

    Fields (read-only arrays):

    - ``scale``: d, the unit of each parameter in the equilibrated problem (p = d z).
    - ``singular_values``: s_1 >= ... >= s_n of the equilibrated whitened rows G diag(d) (eqn 44's
      Lambda for the augmented A'), or the square roots of the eigenvalues of diag(d) I diag(d).
    - ``directions``: V^t, row k the k-th direction v_k in the scaled parameters z.
    - ``rows``: G diag(d), the equilibrated rows it was built from (readings, then priors); None when
      built from an information matrix.
    - ``information``: I = G^t G in physical units when built from an information matrix (else None).
    - ``rtol``: s_k <= rtol s_1 marks v_k undetermined.
    """

    scale: np.ndarray
    singular_values: np.ndarray
    directions: np.ndarray
    rows: np.ndarray | None = None
    information: np.ndarray | None = None
    rtol: float = ILL_CONDITIONED

    def __post_init__(self):
        for name in ("scale", "singular_values", "directions", "rows", "information"):
            object.__setattr__(self, name, readonly(getattr(self, name)))

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_rows(cls, data_rows: np.ndarray, prior_precision: np.ndarray | None = None,
                  scale: np.ndarray | None = None) -> "LinearAnalysis":
        """From the whitened sensitivity rows A' (m x n, physical units) and the prior precision
        diag C_p0^-1 (0 where a parameter has no prior; None: no prior rows), equilibrated by
        `scale` (default: the rows' column norms). C_p = (A'^t A' + C_p0^-1)^-1, eqn 55."""
        data_rows = np.asarray(data_rows, float)
        if scale is None:
            norms = np.linalg.norm(data_rows, axis=0)
            if prior_precision is not None:
                norms = np.sqrt(norms ** 2 + np.asarray(prior_precision, float))
            scale = np.where(norms > 0, 1.0 / np.where(norms > 0, norms, 1.0), 1.0)
        scale = np.asarray(scale, float)
        rows = data_rows * scale
        if prior_precision is not None:  # the prior's rows sqrt(C_p0^-1): priors are observations
            rows = np.vstack([rows, np.diag(np.sqrt(prior_precision) * scale)])
        return cls._of_rows(rows, scale)

    @classmethod
    def _of_rows(cls, rows: np.ndarray, scale: np.ndarray) -> "LinearAnalysis":
        _, s, Vt = np.linalg.svd(rows, full_matrices=False)
        return cls(scale, s, Vt, rows=rows)

    @classmethod
    def from_information(cls, information: np.ndarray, scale: np.ndarray | None = None) -> "LinearAnalysis":
        """From an information matrix I = A'^t A' + C_p0^-1 (physical units), equilibrated by
        `scale` (default 1 / sqrt(diag I), 1 where the diagonal is 0). C_p = I^-1, eqn 55."""
        M = np.asarray(information, float)
        if scale is None:
            d = np.sqrt(np.abs(np.diag(M)))
            scale = np.where(d > 0, 1.0 / np.where(d > 0, d, 1.0), 1.0)
        scale = np.asarray(scale, float)
        lam, W = np.linalg.eigh(M * np.outer(scale, scale))
        lam, W = lam[::-1], W[:, ::-1]
        return cls(scale, np.sqrt(np.clip(lam, 0, None)), W.T, information=M, rtol=float(np.sqrt(EIGEN_RTOL)))

    # ------------------------------------------------------------------ the posterior (eqn 55)
    @cached_property
    def undetermined(self) -> np.ndarray:
        """Which directions v_k the readings and priors do not determine (s_k <= rtol s_1)."""
        s = self.singular_values
        return s <= self.rtol * s[0] if len(s) else np.zeros(0, bool)

    @cached_property
    def scaled_covariance(self) -> np.ndarray:
        """C_z = V_+ S_+^-2 V_+^t, the posterior covariance of the scaled parameters z = p / d."""
        tiny, s, Vt = self.undetermined, self.singular_values, self.directions
        inv2 = np.where(tiny, 0.0, 1.0 / np.where(tiny, 1.0, s) ** 2)
        return readonly((Vt.T * inv2) @ Vt)

    @cached_property
    def covariance(self) -> np.ndarray:
        """C_p = (A'^t A' + C_p0^-1)^-1 (eqn 55) over the determined directions."""
        return readonly(self.scaled_covariance * np.outer(self.scale, self.scale))

    @cached_property
    def involved(self) -> np.ndarray:
        """Parameters with a component above INVOLVED on an undetermined direction."""
        tiny = self.undetermined
        if not tiny.any():
            return np.zeros(len(self.scale), bool)
        return np.abs(self.directions[tiny]).max(axis=0) > INVOLVED

    @cached_property
    def std(self) -> np.ndarray:
        """sqrt(diag C_p); infinite for a parameter involved in an undetermined combination."""
        std = np.sqrt(np.clip(np.diag(self.covariance), 0, None))
        if self.undetermined.any():
            std = np.where(self.involved, np.inf, std)
        return readonly(std)

    @property
    def undetermined_directions(self) -> np.ndarray:
        """Rows: the undetermined directions v_k in the scaled parameters (relative changes when d = |p|)."""
        return self.directions[self.undetermined]

    # ------------------------------------------------------------------ predictions
    def prediction_covariance(self, G: np.ndarray) -> np.ndarray:
        """C_q = G C_p G^t for predictions q with sensitivities G = dq/dp (first order)."""
        return G @ self.covariance @ G.T

    def prediction_variance(self, G: np.ndarray) -> np.ndarray:
        """var q_i = g_i^t C_p g_i for each row g_i^t of G (eqn 55 propagated to first order);
        infinite for a prediction with a component above INVOLVED on an undetermined direction."""
        G = np.atleast_2d(np.asarray(G, float))
        v = np.einsum("ij,jk,ik->i", G, self.covariance, G)
        if self.undetermined.any():
            Gs = G * self.scale  # q = g^t p = (g d)^t z
            reach = np.abs(Gs @ self.undetermined_directions.T).max(axis=1)
            v = np.where(reach > INVOLVED * np.linalg.norm(Gs, axis=1), np.inf, v)
        return v

    def prediction_std(self, G: np.ndarray) -> np.ndarray:
        """sqrt(var q_i) (``prediction_variance``)."""
        return np.sqrt(np.clip(self.prediction_variance(G), 0, None))

    # ------------------------------------------------------------------ data worth
    def conditional(self, rows: np.ndarray) -> "LinearAnalysis":
        """The posterior with more whitened readings: `rows` = A_c' = L_c^-1 A_c (k x n, physical
        units) appended to G, C_p,c = (G^t G + A_c'^t A_c')^-1 (eqn 55 with the candidate's readings;
        data worth), on this analysis' equilibration."""
        rows = np.atleast_2d(np.asarray(rows, float))
        if self.rows is not None:
            return self._of_rows(np.vstack([self.rows, rows * self.scale]), self.scale)
        return LinearAnalysis.from_information(self.information + rows.T @ rows, self.scale)
