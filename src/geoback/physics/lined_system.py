"""The lined configuration of a staged simulation as linear algebra: the ground's Schur complement
on the wall dofs, the readings' view of the wall, the dense interface solve, and the assembled
ground-and-lining system used once the ground keeps being refactorised (the choice between them
and the formulas are in ``staged.py``'s docstring). A mixin of ``StagedSimulation``: it reads the
simulation's `fe`, `ring`, `survey`, `_factor`, `_cond`, `_lfactor`, `_wall_order`, `counters` and
`backend`."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from geoback.physics.elastic import proportion
from geoback.physics.simulation import Stopwatch


@dataclass
class Condensation:
    """The lined configuration's factorised form for one ground factorisation (reference scale):
    the ground's Schur complement on the wall dofs and the readings' view of the wall."""

    fact: object
    PW: np.ndarray  # P K_ref^-1 U  (readings x wall dofs)
    Sigma: np.ndarray  # K_WW - K_WI K_II^-1 K_IW of K_ref = (U^t K_ref^-1 U)^-1


class Interface:
    """The lined solve at ground scale s: with Sigma_s = s Sigma_ref and the lining's S on the wall,
    (I + G S) z = q  <=>  (Sigma_s + S) z = Sigma_s q  (SPD, one dense Cholesky per values)."""

    def __init__(self, cond: Condensation, s: float, S: np.ndarray):
        self.cond, self.s, self.S = cond, s, S
        self.Sigma = s * cond.Sigma
        M = self.Sigma + S
        self.chol = sla.cho_factor(0.5 * (M + M.T), lower=True, check_finite=False)

    def solve(self, q: np.ndarray) -> np.ndarray:
        """z_w for a ground-side solution with wall values q (= U^t K_g^-1 rhs)."""
        return self.solve_sigma(self.Sigma @ q)

    def solve_sigma(self, sq: np.ndarray) -> np.ndarray:
        """z_w from Sigma_s q (avoids G = Sigma^-1 where Sigma_s q is known directly)."""
        return sla.cho_solve(self.chol, sq, check_finite=False)

    @property
    def PW(self) -> np.ndarray:
        return self.cond.PW / self.s


class LinedSystem:
    """The lined configuration's factorised forms (see the module docstring)."""

    def _condensation(self, fact) -> Condensation:
        """Sigma and PW for the ground's current factorisation (reference coefficients)."""
        if self._cond is not None and self._cond.fact is fact:
            return self._cond
        t0 = time.perf_counter()
        Sigma = self._wall_schur(self._factor[0])
        PW = self._wall_view(fact)
        self.counters.factorisations += 1
        self.counters.seconds_factorising += time.perf_counter() - t0
        self._cond = Condensation(fact, PW, Sigma)
        return self._cond

    def _wall_view(self, fact) -> np.ndarray:
        """PW = P K_ref^-1 U: the readings' view of the wall dofs."""
        U = self.ring.wall_dofs
        P = self.survey.P
        if P.shape[0] <= len(U):  # PW = (K^-1 P^t)^t U: one back-substitution per reading
            PW = np.asarray(self._solve(fact, 1.0, np.asarray(P.T.todense()))[U]).T
        else:  # or one per wall dof
            E = np.zeros((self.fe.nfree, len(U)))
            E[U, np.arange(len(U))] = 1.0
            PW = np.asarray(P @ self._solve(fact, 1.0, E))
        return PW

    def _wall_schur(self, coeffs: np.ndarray) -> np.ndarray:
        """The ground's Schur complement on the wall dofs: the trailing block L_WW U_WW of a sparse
        LU of K_g with the wall dofs last (SuperLU, symmetric mode, diagonal pivots; the interior
        in a fill-reducing order found once per mesh)."""
        import scipy.sparse as sp
        import scipy.sparse.linalg as spla

        upper = self.fe.matrix(coeffs)
        K = (upper + sp.triu(upper, k=1).T).tocsc()
        n, U = K.shape[0], self.ring.wall_dofs
        nw = len(U)
        options = dict(diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        if self._wall_order is None:
            inner = np.setdiff1d(np.arange(n), U)
            lu = spla.splu(K[inner][:, inner], permc_spec="MMD_AT_PLUS_A", **options)
            self._wall_order = np.concatenate([inner[np.argsort(lu.perm_c)], U])
        order = self._wall_order
        lu = spla.splu(K[order][:, order].tocsc(), permc_spec="NATURAL", **options)
        if np.any(lu.perm_r != np.arange(n)) or np.any(lu.perm_c != np.arange(n)):
            raise RuntimeError("SuperLU reordered the wall-last matrix: the trailing block is no Schur complement")
        Sigma = (lu.L.tocsc()[n - nw:, n - nw:] @ lu.U.tocsr()[n - nw:, n - nw:]).toarray()
        return 0.5 * (Sigma + Sigma.T)

    def _augmented_index(self) -> np.ndarray:
        """Ring free dof -> unknown of the assembled lined system (ground free dofs, then inner ring)."""
        ring = self.ring
        idx = np.empty(ring.fe.nfree, np.int64)
        idx[ring.o] = ring.wall_dofs
        idx[ring.i] = self.fe.nfree + np.arange(len(ring.i))
        return idx

    def _embed_ring(self, upper, n: int):
        """The ring's (upper CSR, ring free dofs) matrix as an upper matrix of the lined system."""
        import scipy.sparse as sp

        c = upper.tocoo()
        idx = self._augmented_index()
        r, k = idx[c.row], idx[c.col]
        lo, hi = np.minimum(r, k), np.maximum(r, k)
        return sp.csr_matrix((c.data, (lo, hi)), shape=(n, n))

    def _lined_matrix(self, ground_coeffs: np.ndarray, ring_coeffs: np.ndarray):
        import scipy.sparse as sp

        n = self.fe.nfree + len(self.ring.i)
        Kg = self.fe.matrix(ground_coeffs).tocoo()
        K = sp.csr_matrix((Kg.data, (Kg.row, Kg.col)), shape=(n, n)) + self._embed_ring(self.ring.fe.matrix(ring_coeffs), n)
        K.sum_duplicates()
        K.sort_indices()
        return K

    def _lined_factorised(self, ground_coeffs: np.ndarray, ring_coeffs: np.ndarray):
        """Factorisation of the assembled lined matrix and its scale against the kept one."""
        from geoback.physics.solver import Factorisation

        coeffs = np.concatenate([np.asarray(ground_coeffs, float).ravel(), np.asarray(ring_coeffs, float).ravel()])
        if self._lfactor is not None:
            s = proportion(coeffs, self._lfactor[0])
            if s is not None and s > 0:
                return self._lfactor[1], s
            self._lfactor[1].release()
        with Stopwatch(self.counters, "seconds_assembling"):
            K = self._lined_matrix(ground_coeffs, ring_coeffs)
        with Stopwatch(self.counters, "seconds_factorising"):
            fact = Factorisation(K, self.backend)
        self.counters.factorisations += 1
        self._lfactor = (coeffs, fact)
        return fact, 1.0

