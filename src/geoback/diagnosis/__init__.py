"""`geoback diagnose`: locate the mismatch, name the missing physics, model it, show the fit improve."""
from .hypotheses import KINDS, Hypothesis, candidate_hypotheses
from .procedure import Diagnosis, diagnose
from .report import diagnosis_text, write_diagnosis

__all__ = ["KINDS", "Hypothesis", "candidate_hypotheses", "Diagnosis", "diagnose", "diagnosis_text",
           "write_diagnosis"]
