"""Sparse symmetric positive-definite solves that keep their factorisation for reuse.

The matrix is passed as its upper triangle (CSR, diagonal included). Backends:
``pardiso`` (Intel MKL PARDISO through pypardiso, Cholesky, mtype 2) when installed, else
``scipy`` (SuperLU with COLAMD ordering; DESIGN.md: its default MMD_AT_PLUS_A is ~30x slower).
"""
from __future__ import annotations

import os

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


def available_backends() -> list[str]:
    names = []
    try:
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


class Factorisation:
    """Factor of one SPD matrix (given as upper CSR); solve() is a back-substitution."""

    def __init__(self, upper: sp.csr_matrix, backend: str | None = None):
        self.n = upper.shape[0]
        self.backend = backend or default_backend(self.n)
        if self.backend == "pardiso":
            import pypardiso

            self._solver = pypardiso.PyPardisoSolver(mtype=2)
            self._solver.set_statistical_info_off()
            self._matrix = upper
            self._solver.factorize(upper)
        else:
            full = (upper + sp.triu(upper, k=1, format="csr").T).tocsc()
            self._lu = spla.splu(full, permc_spec="COLAMD")

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        rhs = np.asarray(rhs, dtype=float)
        if self.backend == "pardiso":
            out = self._solver.solve(self._matrix, rhs)
        else:
            out = self._lu.solve(rhs)
        return np.asarray(out).reshape(rhs.shape)

    def release(self) -> None:
        if self.backend == "pardiso":
            self._solver.free_memory(everything=True)
