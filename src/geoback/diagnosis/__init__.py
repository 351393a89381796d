"""`geoback diagnose`: locate the mismatch, name the missing physics, model it, show the fit improve.

The extension table (``extensions.py``) is read by the simulation; importing it does not load the
rest of this package.
"""
from __future__ import annotations

__all__ = ["KINDS", "Hypothesis", "candidate_hypotheses", "Diagnosis", "diagnose", "diagnosis_text",
           "write_diagnosis"]

_LAZY = {"KINDS": ".hypotheses", "Hypothesis": ".hypotheses", "candidate_hypotheses": ".hypotheses",
         "Diagnosis": ".procedure", "diagnose": ".procedure", "diagnosis_text": ".report",
         "write_diagnosis": ".report"}


def __getattr__(name: str):
    if name in _LAZY:
        from importlib import import_module

        return getattr(import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module 'geoback.diagnosis' has no attribute '{name}'")
