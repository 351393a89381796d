"""The lined configuration of a staged simulation as linear algebra: the ground's Schur complement
on the wall dofs, the readings' view of the wall, the dense interface solve, and the assembled
ground-and-lining system used once the ground keeps being refactorised (the choice between them
and the formulas are in ``staged.py``'s docstring).

``LinedSystem`` is a component built from explicit inputs (the FE model, the lining's ring, the
counters and the sparse backend); the ground's factorisation, its reference coefficients and the
readings' operator P are passed to the calls that need them. It keeps what does not depend on the
survey: the assembled lined matrix's factorisation (a ``FactorCache``) and the wall-last ordering
of the ground's dofs. The per-survey ``Condensation`` is kept by the simulation reading a survey.
"""
from __future__ import annotations

import copy
import time
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from geoback.physics.simulation import Counters
from geoback.physics.stiffness import FactorCache, counted_solve


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
    """The lined configuration's factorised forms on one FE model and lining ring (module docstring).

    condense: take the condensed form while the ground's factorisation is reused (the default);
    False assembles and factorises the lined configuration from the start (benchmarks compare)."""

    def __init__(self, fe, ring, counters: Counters, backend: str | None = None):
        self.fe, self.ring, self.counters, self.backend = fe, ring, counters, backend
        self.assembled = FactorCache(counters, backend)  # the ground-and-lining matrix's factorisation
        self.condense = True
        self._wall_order: np.ndarray | None = None  # ground dofs, the wall's last (for its Schur complement)

    def __copy__(self):
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__)
        new.assembled = copy.copy(self.assembled)
        return new

    def release(self) -> None:
        self.assembled.release()

    # ------------------------------------------------------------------ condensed onto the wall
    def condensation(self, fact, coeffs: np.ndarray, P) -> Condensation:
        """Sigma and PW for the ground's factorisation `fact` of K_g(coeffs) (reference coefficients),
        read by P; counted as one factorisation."""
        t0 = time.perf_counter()
        Sigma = self.wall_schur(coeffs)
        PW = self.wall_view(fact, P)
        self.counters.factorisations += 1
        self.counters.seconds_factorising += time.perf_counter() - t0
        return Condensation(fact, PW, Sigma)

    def wall_view(self, fact, P) -> np.ndarray:
        """PW = P K_ref^-1 U: the readings' view of the wall dofs."""
        U = self.ring.wall_dofs
        if P.shape[0] <= len(U):  # PW = (K^-1 P^t)^t U: one back-substitution per reading
            PW = np.asarray(counted_solve(self.counters, fact, 1.0, np.asarray(P.T.todense()))[U]).T
        else:  # or one per wall dof
            E = np.zeros((self.fe.nfree, len(U)))
            E[U, np.arange(len(U))] = 1.0
            PW = np.asarray(P @ counted_solve(self.counters, fact, 1.0, E))
        return PW

    def wall_schur(self, coeffs: np.ndarray) -> np.ndarray:
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

    # ------------------------------------------------------------------ assembled
    def augmented_index(self) -> np.ndarray:
        """Ring free dof -> unknown of the assembled lined system (ground free dofs, then inner ring)."""
        ring = self.ring
        idx = np.empty(ring.fe.nfree, np.int64)
        idx[ring.o] = ring.wall_dofs
        idx[ring.i] = self.fe.nfree + np.arange(len(ring.i))
        return idx

    def embed_ring(self, upper, n: int):
        """The ring's (upper CSR, ring free dofs) matrix as an upper matrix of the lined system."""
        import scipy.sparse as sp

        c = upper.tocoo()
        idx = self.augmented_index()
        r, k = idx[c.row], idx[c.col]
        lo, hi = np.minimum(r, k), np.maximum(r, k)
        return sp.csr_matrix((c.data, (lo, hi)), shape=(n, n))

    def lined_matrix(self, ground_coeffs: np.ndarray, ring_coeffs: np.ndarray):
        import scipy.sparse as sp

        n = self.fe.nfree + len(self.ring.i)
        Kg = self.fe.matrix(ground_coeffs).tocoo()
        K = sp.csr_matrix((Kg.data, (Kg.row, Kg.col)), shape=(n, n)) + self.embed_ring(self.ring.fe.matrix(ring_coeffs), n)
        K.sum_duplicates()
        K.sort_indices()
        return K

    def factorised(self, ground_coeffs: np.ndarray, ring_coeffs: np.ndarray):
        """Factorisation of the assembled lined matrix and its scale against the kept one."""
        coeffs = np.concatenate([np.asarray(ground_coeffs, float).ravel(), np.asarray(ring_coeffs, float).ravel()])
        return self.assembled.factorised(coeffs, lambda: self.lined_matrix(ground_coeffs, ring_coeffs))
