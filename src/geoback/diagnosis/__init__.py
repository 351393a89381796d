"""`geoback diagnose`: locate the mismatch, name the missing physics, model it, show the fit improve.

Its files and words (diagnosis.md, diagnosis.json) are written by ``geoback.reports.diagnosis_report``.
"""
from __future__ import annotations

__all__ = ["KINDS", "Hypothesis", "candidate_hypotheses", "Diagnosis", "diagnose"]

_LAZY = {"KINDS": ".hypotheses", "Hypothesis": ".hypotheses", "candidate_hypotheses": ".hypotheses",
         "Diagnosis": ".procedure", "diagnose": ".procedure"}


def __getattr__(name: str):
    if name in _LAZY:
        from importlib import import_module

        return getattr(import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module 'geoback.diagnosis' has no attribute '{name}'")


def __dir__():
    return sorted(set(globals()) | set(__all__))
