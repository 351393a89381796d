"""Sparse symmetric positive-definite solves that keep their factorisation for reuse.

The matrix is passed as its upper triangle (CSR, diagonal included). Backends:
``pardiso`` (Intel MKL PARDISO through pypardiso, Cholesky, mtype 2) when installed, else
``scipy`` (SuperLU in symmetric mode: MMD on A^t + A, diagonal pivots).
"""
from __future__ import annotations

import os

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


def point_pypardiso_at_mkl() -> None:
    """pypardiso looks for libmkl_rt by a recursive glob over the environment on every new
    solver (about 0.3 s); tell it once where the pip-installed library is."""
    if os.environ.get("PYPARDISO_MKL_RT"):
        return
    import glob
    import sys

    for root in (sys.prefix, sys.base_prefix):
        found = sorted(glob.glob(os.path.join(root, "lib", "libmkl_rt.so*")), key=len)
        if found:
            os.environ["PYPARDISO_MKL_RT"] = found[0]
            return


def available_backends() -> list[str]:
    names = []
    try:
        point_pypardiso_at_mkl()
        import pypardiso  # noqa: F401
        names.append("pardiso")
    except ImportError:  # pragma: no cover - platform without MKL
        pass
    names.append("scipy")
    return names


SMALL = 20000  # below this many unknowns SuperLU is as fast as PARDISO and has no threading overhead


def default_backend(n: int | None = None) -> str:
    """GEOBACK_SOLVER if set; else PARDISO for large systems, SuperLU for small ones."""
    wanted = os.environ.get("GEOBACK_SOLVER")
    if wanted:
        if wanted not in available_backends():
            raise ValueError(f"GEOBACK_SOLVER={wanted} is not available here ({', '.join(available_backends())})")
        return wanted
    if n is not None and n < SMALL:
        return "scipy"
    return available_backends()[0]


SPAN_TOL = 1e-12  # a right-hand side this close to the span of earlier ones reuses their solutions
MAX_BASIS = 8  # n x 8 x 2 floats kept per factorisation (90 MB at 700 k DOFs)


class Factorisation:
    """Factor of one SPD matrix (given as upper CSR); solve() is a back-substitution.

    Solutions are remembered: a right-hand side that is a linear combination of earlier ones
    (to SPAN_TOL) is answered from them without a back-substitution. Loads of excavations are
    linear in K0 and the release factor, so after a couple of solves a whole identification
    with one modulus needs no more (eqns 41-42 taken one step further).
    """

    def __init__(self, upper: sp.csr_matrix, backend: str | None = None):
        self.n = upper.shape[0]
        self.backend = backend or default_backend(self.n)
        self.backsubstitutions = 0
        self._raw = _SpanBasis(self.n, self.n)  # right-hand sides met so far and their solutions
        self._coords: dict[int, _SpanBasis] = {}  # the same, keyed by the caller's coordinates
        if self.backend == "pardiso":
            point_pypardiso_at_mkl()  # before pypardiso is imported: it looks for MKL at import
            import pypardiso

            self._solver = pypardiso.PyPardisoSolver(mtype=2)
            self._solver.set_statistical_info_off()
            self._matrix = upper
            self._solver.factorize(upper)
        else:
            full = (upper + sp.triu(upper, k=1, format="csr").T).tocsc()
            # SPD: symmetric ordering on A^t + A with diagonal pivots (3-4x faster than COLAMD with
            # partial pivoting; MMD_AT_PLUS_A is slow only WITH partial pivoting, as DESIGN.md measured)
            self._lu = spla.splu(full, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                                 options={"SymmetricMode": True})

    def _backsolve(self, rhs: np.ndarray) -> np.ndarray:
        self.backsubstitutions += rhs.shape[1]
        if self.backend == "pardiso":
            out = self._solver.solve(self._matrix, np.ascontiguousarray(rhs))
        else:  # SuperLU is much slower on a block of columns than on each column in turn
            out = np.column_stack([self._lu.solve(np.ascontiguousarray(rhs[:, j])) for j in range(rhs.shape[1])])
        return np.asarray(out).reshape(rhs.shape)

    def solve(self, rhs, coords: np.ndarray | None = None) -> np.ndarray:
        """K^-1 rhs for one or several right-hand sides (columns).

        coords: the right-hand sides' coordinates in a small space of the caller's (rhs = M coords
        for a fixed linear map M, e.g. loads from the stresses at the wall's quadrature points).
        The span test is then made on the coordinates, whose rounding does not grow with the
        number of unknowns; without them it is made on the right-hand sides themselves. With
        coords, rhs may be a function of the list of columns to build: it is then called only for
        the right-hand sides the span cannot answer.
        """
        if callable(rhs):
            keys = np.asarray(coords, dtype=float)
            shape = (self.n,) if keys.ndim == 1 else (self.n, keys.shape[1])
            keys = keys.reshape(keys.shape[0], -1)
            build = rhs
        else:
            rhs = np.asarray(rhs, dtype=float)
            shape = rhs.shape
            B = rhs.reshape(self.n, -1)
            keys = B if coords is None else np.asarray(coords, dtype=float).reshape(-1, B.shape[1])
            build = (lambda cols: B[:, cols])
        keys = np.asfortranarray(keys)  # its columns contiguous: the span test reads them one by one
        basis = self._raw if coords is None else \
            self._coords.setdefault(keys.shape[0], _SpanBasis(keys.shape[0], self.n))
        out = np.zeros((self.n, keys.shape[1]))
        todo = []
        for j in range(keys.shape[1]):
            hit = basis.lookup(keys[:, j])
            if hit is None:
                todo.append(j)
            else:
                out[:, j] = hit
        if todo:
            X = self._backsolve(np.asarray(build(todo), dtype=float).reshape(self.n, len(todo)))
            for k, j in enumerate(todo):
                out[:, j] = X[:, k]
                basis.remember(keys[:, j], X[:, k])
        return out.reshape(shape)

    def release(self) -> None:
        if self.backend == "pardiso":
            self._solver.free_memory(everything=True)


class _SpanBasis:
    """Orthonormal basis Q of the keys met so far (columns) and the solutions U = K^-1 (M Q), so
    that a key in their span is answered as U c without a back-substitution."""

    def __init__(self, dim: int, n: int):
        self.Q = np.zeros((dim, 0))
        self.U = np.zeros((n, 0))

    def lookup(self, key: np.ndarray) -> np.ndarray | None:
        nk = np.linalg.norm(key)
        if nk == 0:
            return np.zeros(self.U.shape[0])
        c = self.Q.T @ key
        if np.linalg.norm(key - self.Q @ c) <= SPAN_TOL * nk:
            return self.U @ c
        return None

    def remember(self, key: np.ndarray, x: np.ndarray) -> None:
        if self.Q.shape[1] >= MAX_BASIS:
            return
        c = self.Q.T @ key
        q = key - self.Q @ c
        c2 = self.Q.T @ q  # re-orthogonalise once (classical Gram-Schmidt twice is enough)
        q -= self.Q @ c2
        c += c2
        nq = np.linalg.norm(q)
        if nq <= 1e-10 * np.linalg.norm(key):
            return
        self.Q = np.column_stack([self.Q, q / nq])
        self.U = np.column_stack([self.U, (x - self.U @ c) / nq])


_OPENBLAS = None


def sequential_blas():
    """One OpenBLAS thread (a context manager) for work made of many small dense operations (norms, span
    tests, element loops): on a busy machine its threads cost a hundred times the work itself (1.2 s against
    120 s for a 40 x 40 objective slice of the staged tunnel, and a norm of 12 k numbers 2 ms against 3 us,
    measured on two shared cores). MKL, which PARDISO uses, is left alone."""
    global _OPENBLAS
    if _OPENBLAS is None:
        from threadpoolctl import ThreadpoolController

        _OPENBLAS = ThreadpoolController().select(internal_api="openblas")
    return _OPENBLAS.limit(limits=1)
