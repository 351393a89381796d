"""Factorisation of general (non-symmetric) sparse matrices, with counters.

The consistent tangent of Mohr-Coulomb with non-associated flow is not symmetric, so the SPD
solver of ``geoback.physics.solver`` does not apply. Backends: ``pardiso`` (Intel MKL PARDISO via
pypardiso, real unsymmetric, mtype 11; the analysis is kept for all matrices of one pattern) from
``SMALL`` unknowns up when installed, else ``scipy`` (SuperLU, minimum-degree ordering of A + A^t
with threshold pivoting, ``SUPERLU``). ``GEOBACK_SOLVER`` chooses, as for the elastic solver. Every
factorisation and every back-substituted column is counted in a shared :class:`Counters`.
"""
from __future__ import annotations

import os
import time
from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from geoback.physics.solver import point_pypardiso_at_mkl, available_backends


@dataclass
class Counters:
    """Work done by one forward run (and its sensitivities)."""

    factorisations: int = 0
    analyses: int = 0  # symbolic analyses (orderings) of a new sparsity pattern (PARDISO phase 11)
    factorised_unknowns: int = 0  # summed over the factorisations (per factorisation: the unknowns factorised)
    backsubstitutions: int = 0  # right-hand-side columns solved
    increments: int = 0  # converged load increments
    newton_iterations: int = 0  # linear solves of the Newton corrections (all attempts)
    cutbacks: int = 0  # increments halved after a failed Newton
    apex_points: int = 0  # point updates that fell back to the apex (see mohr_coulomb.APEX)
    warm_starts: int = 0  # increments whose Newton iteration started from an earlier run's solution
    elastic_steps: int = 0  # increments every point reached elastically: one exact linear step, no Newton
    condensations: int = 0  # elastic parts condensed onto a region that may yield (condensed.py)
    condensations_reused: int = 0  # runs that reused the last run's condensation (scaled)
    seconds: dict = field(default_factory=lambda: defaultdict(float))

    def timed(self, key: str):
        return _Timer(self.seconds, key)

    def summary(self) -> dict:
        out = {k: getattr(self, k) for k in ("factorisations", "analyses", "factorised_unknowns", "backsubstitutions", "increments",
                                               "newton_iterations", "cutbacks", "apex_points", "warm_starts",
                                               "elastic_steps", "condensations", "condensations_reused")}
        out["seconds"] = {k: round(v, 4) for k, v in self.seconds.items()}
        return out


class _Timer:
    def __init__(self, store, key):
        self.store, self.key = store, key

    def __enter__(self):
        self.t0 = time.perf_counter()

    def __exit__(self, *exc):
        self.store[self.key] += time.perf_counter() - self.t0


class SingularMatrix(RuntimeError):
    """The backend could not factorise the matrix (singular to working precision)."""


# a SuperLU pivot this small against the largest: the matrix is singular to working precision (a tangent
# with a mechanism: SuperLU factorised it without a word and its solves were garbage, some printing BLAS
# errors 'On entry to DTRSV parameter number 6 had an illegal value' on stderr); measured 1e-17 there
PIVOT = 1e-14
SMALL = 1000  # below this many unknowns SuperLU's factorisations cost little either way (default_backend)
# The tangent's pattern is symmetric (only its values are not): a minimum-degree ordering of A + A^t with
# diagonal pivots preferred (threshold partial pivoting at 0.1) fills less than COLAMD; measured on a
# 2.4 k-DOF Mohr-Coulomb tangent, 7-9 ms per factorisation against 9-14 ms (busy 2-core machine).
SUPERLU = dict(permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1, options={"SymmetricMode": True})


def default_backend(n: int) -> str:
    """GEOBACK_SOLVER if set; else PARDISO (when installed) from SMALL unknowns up, SuperLU below.
    Measured on Mohr-Coulomb tangents with one thread (as the runs use), PARDISO refactorising with
    its analysis kept (phase 22) against SuperLU: 0.73 against 1.7 ms at 0.9 k DOFs, 1.6 against 3.7 ms
    at 1.7 k, 4.1 against 8.9 ms at 3.4 k (`geoback run cases/plastic-tunnel.yaml`, 2.4 k DOFs: 4.6
    against 5.3 s CPU). (An earlier measurement on a busy machine, with MKL's threads and the analysis
    counted, had SuperLU ahead up to about 10 k DOFs.)"""
    wanted = os.environ.get("GEOBACK_SOLVER")
    if wanted:
        if wanted not in available_backends():
            raise ValueError(f"GEOBACK_SOLVER={wanted} is not available here ({', '.join(available_backends())})")
        return wanted
    return "scipy" if n < SMALL else available_backends()[0]


class Released:
    """A factorisation whose memory is PARDISO's (MKL's, not Python's): ``release()`` frees it, and so
    does dropping the object without it (factorisations kept from run to run, ``condensed.Region``)."""

    def release(self) -> None:  # pragma: no cover - every subclass frees its own
        pass

    def __del__(self):
        try:
            self.release()
        except Exception:  # noqa: BLE001 - (at interpreter exit MKL may be gone already)
            pass


class LU(Released):
    """LU factorisation of square CSR matrices of one sparsity pattern.

    ``factorise(A)`` replaces the factor; with PARDISO the symbolic analysis (ordering, phase
    11) is done for the first matrix only and every later matrix of the same pattern costs a
    numerical factorisation (phase 22), about half of a full one. ``solve`` back-substitutes one
    or more columns (phase 33; iterative refinement where pivots were perturbed)."""

    def __init__(self, counters: Counters, backend: str | None = None):
        self.counters = counters
        self.backend = backend
        self._A = None
        self._solver = None
        self._pattern = None

    def factorise(self, A: sp.csr_matrix, plastic=None, near=None) -> "LU":
        self.n = A.shape[0]
        if self.backend is None:
            self.backend = default_backend(self.n)
        if self.backend not in available_backends():
            raise ValueError(f"solver backend {self.backend!r} is not available ({', '.join(available_backends())})")
        self._A = None
        if not np.isfinite(A.data).all():  # SuperLU factorises NaN silently and its solves print BLAS errors
            raise SingularMatrix("the matrix has entries that are not finite numbers")
        with self.counters.timed("factorise"):
            try:
                if self.backend == "pardiso":
                    self._pardiso(A)
                else:
                    self._lu = spla.splu(A.tocsc(), **SUPERLU)
                    pivots = np.abs(self._lu.U.diagonal())
                    if pivots.size and not pivots.min() > PIVOT * pivots.max():
                        raise RuntimeError(f"singular to working precision (smallest pivot {pivots.min():.1e} of "
                                           f"the largest {pivots.max():.1e})")
            except Exception as exc:  # SuperLU: RuntimeError; pypardiso: PyPardisoError
                raise SingularMatrix(f"{self.backend} could not factorise the matrix: {exc}") from None
        self._A = A
        self.counters.factorisations += 1
        self.counters.factorised_unknowns += self.n
        return self

    def _pardiso(self, A: sp.csr_matrix) -> None:
        if not A.has_sorted_indices:
            A.sort_indices()
        if self._solver is None:
            import pypardiso

            point_pypardiso_at_mkl()
            self._solver = pypardiso.PyPardisoSolver(mtype=11)
            self._solver.set_statistical_info_off()
            # every iparm given (iparm[0] = 1): PARDISO's defaults for mtype 11 (nested dissection, pivots perturbed
            # at 1e-13, scaling and matching) but iterative refinement only where pivots were perturbed: by default
            # it refines twice after every solve, measured on Mohr-Coulomb tangents with no pivot perturbed at all
            # (iparm[13] = 0), for back-substitutions 2.4x as costly (1.37 s against 0.58 s in a 50 k-DOF run) and
            # sensitivities that agree to 2.5e-13 either way
            ip = self._solver.iparm
            ip[0], ip[1], ip[7], ip[9], ip[10], ip[12], ip[17] = 1, 2, 0, 13, 1, 1, -1
        same = (self._pattern is not None and np.array_equal(self._pattern[0], A.indptr)
                and np.array_equal(self._pattern[1], A.indices))
        if not same:
            self._solver.set_phase(11)
            self._solver._call_pardiso(A, np.zeros((self.n, 1), order="F"))
            self._pattern = (A.indptr.copy(), A.indices.copy())
            self.counters.analyses += 1
        self._solver.set_phase(22)
        self._solver._call_pardiso(A, np.zeros((self.n, 1), order="F"))

    def attach(self, counters: Counters) -> None:
        """Count this factor's work in `counters` (a new run's; the analysis of the pattern is kept)."""
        self.counters = counters

    def solve(self, rhs: np.ndarray, correction: bool = False) -> np.ndarray:
        """A^-1 rhs (`correction`: a Newton correction, which a condensed factor may solve inexactly; here exact)."""
        if self._A is None:
            raise RuntimeError("solve() before factorise()")
        rhs = np.asarray(rhs, float)
        B = rhs.reshape(self.n, -1)
        if not np.isfinite(B).all():
            raise SingularMatrix("a right-hand side has entries that are not finite numbers")
        with self.counters.timed("backsubstitute"):
            if self.backend == "pardiso":
                self._solver.set_phase(33)
                X = self._solver._call_pardiso(self._A, np.asfortranarray(B))
            else:
                X = np.column_stack([self._lu.solve(np.ascontiguousarray(B[:, j])) for j in range(B.shape[1])])
        self.counters.backsubstitutions += B.shape[1]
        return np.asarray(X).reshape(rhs.shape)

    def release(self) -> None:
        if self._solver is not None:
            self._solver.free_memory(everything=True)
            self._solver = None
        self._A = None
        self._lu = None
        self._pattern = None


