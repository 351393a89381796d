"""geoback: maximum-likelihood back-analysis of excavations (Ledesma, Gens & Alonso 1996).

    from geoback import load_case, identify, diagnose
    loaded = load_case("cases/tunnel-paper.yaml")
    result = identify(loaded)          # .fit.p, .reliability.covariance, ...
    diagnosis = diagnose(loaded)       # .accepted, .final_reliability, ...
"""
from __future__ import annotations

__version__ = "0.1.0"

from .case import load_case  # noqa: E402

__all__ = ["load_case", "identify", "run_case", "diagnose", "Problem", "__version__"]

_LAZY = {"identify": ".identification", "run_case": ".identification", "diagnose": ".diagnosis", "Problem": ".problem"}


def __getattr__(name: str):
    """The heavy parts load on first use, so that `geoback --help` and bad input answer fast."""
    if name in _LAZY:
        from importlib import import_module

        return getattr(import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module 'geoback' has no attribute '{name}'")
