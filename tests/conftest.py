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
