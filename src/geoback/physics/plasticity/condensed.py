"""Factorise only what yields: the elastic part of the mesh condensed onto the region that may yield.

Outside the elements that yield, the consistent tangent K_t of an elastoplastic run is the elastic
stiffness K_e (``incremental._Problem.tangent`` corrects only elements with plastic points). With the
free dofs split into I (touched by no element of the region Y that may yield) and B (the dofs of Y),
and Gamma the dofs of B coupled to I (the interface),

    [ K_II  K_IB ] [x_I]   [b_I]          R = A_BB - E_G (K_GI K_II^-1 K_IG) E_G^t,            (C1)
    [ K_BI  A_BB ] [x_B] = [b_B],         R x_B = b_B - K_BI K_II^-1 b_I,
                                          x_I = K_II^-1 (b_I - K_IB x_B),                        (C2)

where A_BB is the tangent's B block and K_II, K_IB = K_BI^t are elastic. K_II is factorised once
(Cholesky) and the dense Gamma x Gamma correction K_GI K_II^-1 K_IG is made once, as the Schur
complement of K_e on I and Gamma (PARDISO's partial factorisation, iparm[35]); every Newton step then
factorises only R (the region plus a dense interface block: measured at 50 k DOFs with a plastic zone
of 15 % of the points, 0.013 s against 0.12-0.14 s for the whole tangent). (C1)-(C2) is the same linear
algebra as a factorisation of the whole tangent, so solutions and the sensitivities made with them agree
to rounding (tests/test_condensed.py).

``Region`` keeps Y and its condensation from run to run: a return mapping that finds a plastic point
outside Y grows Y, to the plastic elements, the elements close to yielding (``incremental.NEAR`` of their
strength mobilised: the next increments' plastic zone) and ``RINGS`` rings of neighbours, so that the
next increments rarely grow it again, and condenses anew; a run whose elastic stiffness is the last one times a factor (only
moduli changed, the usual step of an identification) reuses the condensation scaled by that factor:
K_II^-1 by 1/s, the correction by s. Only with PARDISO (the Schur complement is its feature) and from
``CONDENSE_FROM`` unknowns up, where a whole factorisation costs enough for the condensation to pay.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from geoback.physics.plasticity.linear import LU, Counters, Released, SingularMatrix
from geoback.physics.solver import point_pypardiso_at_mkl

RINGS = 3  # rings of elements added around the plastic elements when the region grows
CONDENSE_FROM = 10000  # unknowns: below, a whole factorisation is cheap and the condensation does not pay (measured:
# `geoback run` on the shipped plastic case, 2.4 k DOFs, 6.9 s CPU condensed against 5.4 s; an identification at 15 k
# DOFs 9.2 s against 12.0 s, at 50 k 23 s against 45 s)
NEGLIGIBLE = 1e-6  # a Newton residual on the elastic part below this of the whole is not corrected (Condensation.solve)
SAME_SCALE = 1e-12  # an elastic stiffness within this of the last one times a factor reuses its condensation


def keyed(rows: np.ndarray, cols: np.ndarray, ncols: int) -> np.ndarray:
    """Entries (row, col) as row-major keys row * ncols + col (what a sorted CSR pattern lists in order)."""
    return rows.astype(np.int64) * ncols + cols


def pattern(keys: np.ndarray, shape: tuple) -> tuple[np.ndarray, np.ndarray]:
    """(indptr, indices) of the sorted CSR pattern of the sorted unique `keys` (``keyed``)."""
    indptr = np.searchsorted(keys // shape[1], np.arange(shape[0] + 1)).astype(np.int32)
    return indptr, (keys % shape[1]).astype(np.int32)


def _pardiso(mtype: int, schur: bool = False):
    point_pypardiso_at_mkl()
    import pypardiso

    s = pypardiso.PyPardisoSolver(mtype=mtype)
    s.set_statistical_info_off()
    # every iparm given (iparm[0] = 1): nested dissection, pivots perturbed at 1e-8 (none in an SPD matrix), no
    # iterative refinement (by default PARDISO refines twice, tripling the cost of a back-substitution: 17.8 ms
    # against 6 ms measured at 40 k DOFs, for a Cholesky solve accurate without it), and the Schur complement
    s.iparm[0], s.iparm[1], s.iparm[7], s.iparm[9], s.iparm[17] = 1, 2, 0, 8, -1
    s.iparm[35] = 1 if schur else 0
    return s


class _Cholesky(Released):
    """PARDISO Cholesky (mtype 2) of an SPD matrix given as its upper triangle; solve() back-substitutes."""

    def __init__(self, upper: sp.csr_matrix):
        self.n = upper.shape[0]
        self._A = upper
        self._s = _pardiso(2)
        self._s.set_phase(12)
        self._s._call_pardiso(upper, np.zeros((self.n, 1), order="F"))

    def solve(self, B: np.ndarray) -> np.ndarray:
        self._s.set_phase(33)
        return np.asarray(self._s._call_pardiso(self._A, np.asfortranarray(B))).reshape(B.shape)

    def release(self) -> None:
        if self._s is not None:
            self._s.free_memory(everything=True)
            self._s = None


def schur_complement(upper: sp.csr_matrix, last: np.ndarray) -> np.ndarray:
    """S = A_GG - A_GI A_II^-1 A_IG of an SPD matrix (upper triangle) for the rows `last` (boolean),
    dense, by PARDISO's partial factorisation."""
    n, m = upper.shape[0], int(last.sum())
    s = _pardiso(2, schur=True)
    s.perm = last.astype(np.int32)
    try:
        s.set_phase(12)
        x = s._call_pardiso(upper, np.zeros((n, max(1, -(-m * m // n))), order="F"))
    finally:
        s.free_memory(everything=True)
    if s.iparm[35] != 1:  # pragma: no cover - a PARDISO without the Schur complement
        raise RuntimeError("PARDISO did not compute the Schur complement")
    S = np.asarray(x).ravel(order="F")[:m * m].reshape(m, m)
    return 0.5 * (S + S.T)


class Condensation:
    """K_e condensed onto the dofs B of the elements `region` (boolean per element): (C1)-(C2)."""

    def __init__(self, K: sp.csr_matrix, edofs: np.ndarray, region: np.ndarray, counters: Counters):
        n = K.shape[0]
        self.region = region.copy()
        inB = np.zeros(n, bool)
        e = edofs[region]
        inB[e[e >= 0]] = True
        self.B, self.I = np.flatnonzero(inB), np.flatnonzero(~inB)
        self.n, self.scale, self.counters = n, 1.0, counters
        self._K = K  # the elastic stiffness condensed (its pattern: every tangent's)
        with counters.timed("condense"):
            KI = K[self.I]
            self.K_IB = KI[:, self.B].tocsr()
            self.gamma = np.flatnonzero(np.diff(self.K_IB.tocsc().indptr) > 0)  # B positions coupled to I
            self.K_II = _Cholesky(sp.triu(KI[:, self.I], format="csr")) if len(self.I) else None
            if len(self.gamma) and len(self.I):
                keep = np.concatenate([self.I, self.B[self.gamma]])
                order = np.argsort(keep)
                last = np.zeros(len(keep), bool)
                last[len(self.I):] = True
                Kj = K[keep[order]][:, keep[order]]
                S = schur_complement(sp.triu(Kj, format="csr"), last[order])
                G = self.B[self.gamma]
                # S's rows are the Gamma dofs in increasing order, as G
                self.C = K[G][:, G].toarray() - S
            else:
                self.C = np.zeros((len(self.gamma), len(self.gamma)))
            self._pattern()
        counters.condensations += 1

    def _pattern(self) -> None:
        """R's pattern (A_BB's and the dense Gamma block) and where A's entries and C's go in it."""
        nB = len(self.B)
        P = self._K.copy()
        P.data = np.arange(1, P.nnz + 1, dtype=float)  # 1 + position in A.data
        PBB = P[self.B][:, self.B].tocoo()
        g = self.gamma
        at_A = keyed(PBB.row, PBB.col, nB)
        at_C = keyed(np.repeat(g, len(g)), np.tile(g, len(g)), nB)
        keys = np.union1d(at_A, at_C)
        self._indptr, self._indices = pattern(keys, (nB, nB))
        self._from_A = (PBB.data - 1).astype(np.int64)
        self._to_R = np.searchsorted(keys, at_A)
        self._to_C = np.searchsorted(keys, at_C)
        self._nnz = len(keys)

    def matches(self, K: sp.csr_matrix) -> float | None:
        """The factor s with K = s K_e (same pattern) to SAME_SCALE, or None."""
        old = self._K
        if K.shape != old.shape or K.nnz != old.nnz or not np.array_equal(K.indices, old.indices) \
                or not np.array_equal(K.indptr, old.indptr):
            return None
        s = float(K.data @ old.data) / float(old.data @ old.data)
        if s > 0 and np.max(np.abs(K.data - s * old.data)) <= SAME_SCALE * np.max(np.abs(K.data)):
            return s
        return None

    def reduced(self, A: sp.csr_matrix) -> sp.csr_matrix:
        """R of (C1) for a tangent A of K_e's pattern that equals scale * K_e outside the region."""
        if A.nnz != self._K.nnz:
            raise ValueError("the tangent's pattern is not the condensed stiffness'")
        data = np.zeros(self._nnz)
        data[self._to_R] = A.data[self._from_A]
        data[self._to_C] -= self.scale * self.C.ravel()
        nB = len(self.B)
        return sp.csr_matrix((data, self._indices, self._indptr), shape=(nB, nB))

    def solve(self, lu: LU, rhs: np.ndarray, correction: bool = False) -> np.ndarray:
        """(C1)-(C2): K_t^-1 rhs with R factorised in `lu`. A Newton `correction` (one column) whose residual on
        the elastic part is below NEGLIGIBLE of the whole skips K_II^-1 b_I: the elastic rows are linear, so
        after a Newton step their residual is rounding (an inexact Newton step; the residual test decides)."""
        b = np.asarray(rhs, float).reshape(self.n, -1)
        x = np.empty_like(b)
        if not len(self.I):
            return lu.solve(b).reshape(np.shape(rhs))
        s, timed = self.scale, self.counters.timed
        bI = b[self.I]
        skip = not np.any(bI) or (correction and np.linalg.norm(bI) <= NEGLIGIBLE * np.linalg.norm(b))
        with timed("backsubstitute: elastic part"):
            yI = np.zeros_like(bI) if skip else self.K_II.solve(bI) / s
        xB = lu.solve(b[self.B] - s * (self.K_IB.T @ yI)) if len(self.B) else np.zeros((0, b.shape[1]))
        x[self.B] = xB
        with timed("backsubstitute: elastic part"):
            x[self.I] = self.K_II.solve(bI - s * (self.K_IB @ xB)) / s if len(self.B) else yI
        return x.reshape(np.shape(rhs))

    def release(self) -> None:
        if self.K_II is not None:
            self.K_II.release()
            self.K_II = None


def grown(edofs: np.ndarray, n: int, mask: np.ndarray, rings: int) -> np.ndarray:
    """`mask` (per element) with `rings` rings of elements sharing a dof added."""
    mask = mask.copy()
    safe = np.where(edofs >= 0, edofs, 0)
    for _ in range(rings):
        d = np.zeros(n, bool)
        e = edofs[mask]
        d[e[e >= 0]] = True
        mask |= (d[safe] & (edofs >= 0)).any(axis=1)
    return mask


class Region:
    """The elements that may yield and the elastic stiffness condensed onto them, kept from run to run
    (see the module docstring), and a run's two factorisations. ``start(K_e)`` at the start of a
    condensed run; ``covering(plastic)`` the condensation whose region holds the plastic elements
    (growing it if needed); ``factors()`` the factorisations; ``close()`` after a run frees
    condensations no longer current; ``release()`` frees everything."""

    def __init__(self, edofs: np.ndarray, n: int, rings: int = RINGS):
        self.edofs, self.n, self.rings = edofs, n, rings
        self.mask = np.zeros(edofs.shape[0], bool)
        self.current: Condensation | None = None
        self._K = None
        self._retired: list[Condensation] = []
        self._factors: tuple = ()
        self._kind = None

    def factors(self, counters: Counters, backend: str | None, condensed: bool) -> tuple:
        """The two factorisations a run works with (the converged tangent's and the Newton iteration's):
        through this region's condensation, or of whole tangents with `backend`. Kept from run to run,
        so that a pattern seen before is not analysed again (PARDISO's phase 11: at 2.4 k DOFs 6.3 ms,
        three refactorisations; twice a run without them)."""
        kind = ("condensed",) if condensed else ("whole", backend)
        if kind != self._kind:
            for f in self._factors:
                f.release()
            self._factors = ((CondensedLU(self, counters), CondensedLU(self, counters)) if condensed
                             else (LU(counters, backend), LU(counters, backend)))
            self._kind = kind
        for f in self._factors:
            f.attach(counters)
        return self._factors

    def start(self, K: sp.csr_matrix, counters: Counters) -> None:
        """A run with elastic stiffness K begins: keep the condensation if K is the last one scaled."""
        self.counters = counters
        if self.current is not None:
            s = self.current.matches(K)
            if s is not None:
                self.current.scale, self.current.counters = s, counters
                counters.condensations_reused += 1
                return
            self._retire()
        self._K = K

    def covering(self, plastic: np.ndarray, near=None) -> Condensation:
        """The condensation of a region holding the elements `plastic` (indices); grown, it takes in the
        elements `near()` too (close to yielding: the next increments' plastic zone)."""
        if self.current is not None and self.current.region[plastic].all():
            return self.current
        mask = self.mask.copy()
        mask[plastic] = True
        if near is not None and len(plastic):
            mask[near()] = True
        mask = grown(self.edofs, self.n, mask, self.rings)
        K = self._K if self.current is None else self.current._K
        scale = 1.0 if self.current is None else self.current.scale
        self._retire()
        self.mask = mask
        self.current = Condensation(K, self.edofs, mask, self.counters)
        self.current.scale = scale
        return self.current

    def _retire(self) -> None:
        if self.current is not None:
            self._retired.append(self.current)
            self.current = None

    def close(self) -> None:
        for c in self._retired:
            c.release()
        self._retired = []

    def release(self) -> None:
        self._retire()
        self.close()
        for f in self._factors:
            f.release()
        self._factors, self._kind = (), None
        self.mask[:] = False
        self._K = None


class CondensedLU:
    """The interface of ``linear.LU`` (``factorise(A)``, ``solve(rhs)``, ``release()``) for tangents
    factorised through a ``Region``: ``factorise(A, plastic)`` with the elements whose points yield."""

    def __init__(self, region: Region, counters: Counters):
        self.region, self.counters = region, counters
        self._lu = LU(counters)  # R's factor: PARDISO or SuperLU by R's size (linear.default_backend)
        self._cond = None

    def factorise(self, A: sp.csr_matrix, plastic: np.ndarray | None = None, near=None) -> "CondensedLU":
        """`plastic`: the elements whose points yield; `near()`: the elements close to yielding, which a region
        that must grow takes in too (asked only then)."""
        if not np.isfinite(A.data).all():  # (before the region may grow and condense for nothing)
            raise SingularMatrix("the matrix has entries that are not finite numbers")
        cond = self.region.covering(np.zeros(0, int) if plastic is None else plastic, near)
        R = cond.reduced(A)
        if cond is not self._cond:  # a new region: R's size, pattern and backend are new
            self._lu.release()
            self._lu = LU(self.counters)
        if R.shape[0]:
            self._lu.factorise(R)
        self._cond = cond
        return self

    def attach(self, counters: Counters) -> None:
        """Count this factor's work in `counters` (a new run's)."""
        self.counters = counters
        self._lu.attach(counters)

    def solve(self, rhs: np.ndarray, correction: bool = False) -> np.ndarray:
        if self._cond is None:
            raise RuntimeError("solve() before factorise()")
        B = np.asarray(rhs, float)
        if not np.isfinite(B).all():
            raise SingularMatrix("a right-hand side has entries that are not finite numbers")
        if not len(self._cond.B):
            self.counters.backsubstitutions += B.reshape(self._cond.n, -1).shape[1]
        return self._cond.solve(self._lu, B, correction)

    def release(self) -> None:
        self._lu.release()
        self._cond = None
