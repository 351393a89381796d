"""geoback: maximum-likelihood back-analysis of excavations (Ledesma, Gens & Alonso 1996)."""
from __future__ import annotations

__version__ = "0.1.0"

from .case import load_case  # noqa: E402

__all__ = ["load_case", "__version__"]
