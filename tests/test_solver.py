"""Factorisation: both backends, and the span cache of right-hand sides."""
import numpy as np
import pytest
import scipy.sparse as sp

from geoback.physics.solver import MAX_BASIS, Factorisation, available_backends

pytestmark = pytest.mark.quick  # the edit-test loop tier (`pytest -m quick`)


def _spd(n=400, seed=0):
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=0.01, random_state=seed)
    A = A + A.T + sp.eye(n) * (2 + abs(A).sum(axis=1).max())
    return sp.triu(A, format="csr"), A.toarray(), rng


@pytest.mark.parametrize("backend", available_backends())
def test_span_cache_gives_exact_solutions_without_backsubstitution(backend):
    upper, A, rng = _spd()
    f = Factorisation(upper, backend)
    b1, b2 = rng.standard_normal(400), rng.standard_normal(400)
    x1, x2 = f.solve(b1), f.solve(b2)
    assert f.backsubstitutions == 2
    combo = 0.3 * b1 - 2.5 * b2
    x = f.solve(combo)
    assert f.backsubstitutions == 2  # answered from the span of b1, b2
    assert np.allclose(A @ x, combo, rtol=1e-10, atol=1e-10)
    block = f.solve(np.column_stack([b1, combo, rng.standard_normal(400)]))
    assert f.backsubstitutions == 3  # only the new direction is solved
    assert np.allclose(A @ block, np.column_stack([b1, combo, A @ block[:, 2]]), atol=1e-10)
    assert np.allclose(block[:, 0], x1, rtol=1e-12, atol=1e-14)
    assert np.allclose(f.solve(np.zeros(400)), 0.0)


def test_span_cache_is_bounded():
    upper, A, rng = _spd(seed=1)
    f = Factorisation(upper, "scipy")
    B = rng.standard_normal((400, MAX_BASIS + 5))
    X = np.column_stack([f.solve(B[:, j]) for j in range(B.shape[1])])
    assert f.backsubstitutions == B.shape[1]
    assert f._raw.Q.shape[1] == MAX_BASIS
    assert np.allclose(A @ X, B, atol=1e-10)
