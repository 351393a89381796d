"""Test-wide settings: meshes are cached in a temporary folder, never in the user's home."""
import os
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CASES = ROOT / "cases"

if not os.environ.get("GEOBACK_CACHE"):
    os.environ["GEOBACK_CACHE"] = tempfile.mkdtemp(prefix="geoback-test-cache-")


@pytest.fixture
def paper_case_path() -> Path:
    return CASES / "tunnel-paper.yaml"


def central_difference_error(analysis, p, A, j: int, h: float) -> float:
    """Relative difference between column j of the exact sensitivity A = dx/dp at p and the
    central finite difference with step h (analysis: a prepared case, geoback.identification)."""
    import numpy as np

    up, down = p.copy(), p.copy()
    up[j] += h
    down[j] -= h
    fd = (analysis.predict(up).x - analysis.predict(down).x) / (2 * h)
    return float(np.linalg.norm(fd - A[:, j]) / np.linalg.norm(A[:, j]))
