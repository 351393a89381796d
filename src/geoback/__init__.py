"""geoback: maximum-likelihood back-analysis of excavations (Ledesma, Gens & Alonso 1996).

    from geoback import load_case, identify, diagnose
    loaded = load_case("cases/tunnel-paper.yaml")
    analysis = prepare(loaded)         # mesh, FE model, instruments, readings (optional step)
    result = identify(loaded)          # result["E[clay]"].value, .std, .interval; result.report()
    diagnosis = diagnose(loaded)       # .accepted, .final, .baseline
"""
from __future__ import annotations

__version__ = "0.1.0"

from .case import load_case  # noqa: E402

__all__ = ["load_case", "prepare", "identify", "explore", "run_case", "diagnose", "__version__"]

_LAZY = {"prepare": ".identification", "identify": ".identification", "explore": ".explore", "run_case": ".run",
         "diagnose": ".diagnosis"}


def __getattr__(name: str):
    """The heavy parts load on first use, so that `geoback --help` and bad input answer fast."""
    if name in _LAZY:
        from importlib import import_module

        return getattr(import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module 'geoback' has no attribute '{name}'")
