"""Test-wide settings: meshes are cached in a temporary folder, never in the user's home."""
import os
import tempfile
from pathlib import Path

import pytest
from hypothesis import settings


ROOT = Path(__file__).resolve().parents[1]
CASES = ROOT / "cases"

if not os.environ.get("GEOBACK_CACHE"):
    os.environ["GEOBACK_CACHE"] = tempfile.mkdtemp(prefix="geoback-test-cache-")

# Property tests draw the same examples on every run, so CI is reproducible; set
# HYPOTHESIS_PROFILE=explore to draw new ones (a failure prints the example to add as a regression test).
settings.register_profile("reproducible", derandomize=True, database=None)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "reproducible"))


# Tiers: `pytest -m quick` (under 90 s) for the edit-test loop, declared in each test module by
# `pytestmark = pytest.mark.quick` (the numerical core: covariances, solver, FE model, sensitivities,
# the seam, identification, instruments, the house's layout); `pytest` (what CI runs) adds the
# commands, figures, diagnosis, studies and bad-input tests; `pytest -m slow` the long verification runs.
def pytest_collection_modifyitems(config, items):
    for item in items:  # a slow test is never in the quick tier
        if item.get_closest_marker("slow") and item.get_closest_marker("quick"):
            item.own_markers[:] = [m for m in item.own_markers if m.name != "quick"]
            if item.get_closest_marker("quick"):
                raise pytest.UsageError(f"{item.nodeid}: a module marked quick holds a slow test; mark the test, "
                                        "not the module, or move it")


@pytest.fixture
def paper_case_path() -> Path:
    return CASES / "tunnel-paper.yaml"


def central_difference_error(analysis, p, A, j: int, h: float) -> float:
    """Relative difference between column j of the exact sensitivity A = dx/dp at p and the
    central finite difference with step h (analysis: a prepared case, geoback.inference.identification)."""
    import numpy as np

    up, down = p.copy(), p.copy()
    up[j] += h
    down[j] -= h
    fd = (analysis.predict(up).x - analysis.predict(down).x) / (2 * h)
    return float(np.linalg.norm(fd - A[:, j]) / np.linalg.norm(A[:, j]))
