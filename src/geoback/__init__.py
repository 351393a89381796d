"""geoback: maximum-likelihood back-analysis of excavations (Ledesma, Gens & Alonso 1996).

    import geoback
    loaded = geoback.load_case("cases/tunnel-paper.yaml")
    result = geoback.identify(loaded)          # result["E[clay]"].value, .std, .interval
    print(geoback.fit_report(result))          # the fit report (as `geoback run` prints it)
    diagnosis = geoback.diagnose(loaded)       # .accepted, .final, .baseline
    analysis = geoback.prepare(loaded)         # mesh, FE model, instruments, readings (optional step)
    fc = geoback.forecast(analysis, result)    # the case's forecasts with their bands
    d = geoback.design(analysis, result)       # data worth of the case's candidate instruments

The house is in rooms (``docs/architecture.md``): case, observation, physics, inference, worth,
diagnosis, reports, commands; the names above are the public API and load on first use.
"""
from __future__ import annotations

__version__ = "0.1.0"

from geoback.case.loading import load_case  # noqa: E402

_LAZY = {"prepare": "geoback.inference.identification", "identify": "geoback.inference.identification",
         "explore": "geoback.inference.explore", "diagnose": "geoback.diagnosis.procedure",
         "forecast": "geoback.worth.forecast", "design": "geoback.worth.design",
         "fit_report": "geoback.reports.report", "run_case": "geoback.commands.run"}
_ALIASES = {"fit_report": "report_text"}

__all__ = ["load_case", *_LAZY, "__version__"]


def __getattr__(name: str):
    """The heavy parts load on first use, so that `geoback --help` and bad input answer fast."""
    if name in _LAZY:
        from importlib import import_module

        return getattr(import_module(_LAZY[name]), _ALIASES.get(name, name))
    raise AttributeError(f"module 'geoback' has no attribute '{name}'")


def __dir__():
    """The public API first: what tab completion offers."""
    return sorted(set(__all__) | {"__version__"})
