"""How much the readings tell about each parameter: prior -> posterior (the Schur complement of
pyEMU / PEST++'s `.par.usum`) and a per-parameter identifiability between 0 and 1.

With the readings' information at the estimate I = A'^t A' (whitened sensitivities, eqn 55
without the prior rows) and a prior std s0_j for every parameter,

    C_post = (I + diag(1 / s0^2))^-1,     identifiability_j = 1 - C_post,jj / s0_j^2,

(eqn 55 with that prior, solved by ``linear_analysis.LinearAnalysis.from_information``): 0 when
the readings add nothing to the prior, 1 when they fix the parameter far better than the
prior did. The prior is the case's where it gives one; otherwise an uninformed one spanning the
quantity's usual range for ground (``limits``) as its 95 % interval: in ln p for positive
quantities (std ln(hi / lo) / 3.92, taken at the estimate: s0 = p ln(hi / lo) / 3.92), else in p.
The posterior std of a parameter without a case prior is thus a little smaller than the fit's,
which has no prior; both are reported.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geoback.inference.linear_analysis import LinearAnalysis
from geoback.inference.reliability import Z95


@dataclass(frozen=True)
class PriorPosterior:
    names: list[str]
    prior_std: np.ndarray
    prior_source: list[str]  # 'case prior' or 'usual range'
    posterior_std: np.ndarray

    @property
    def reduction(self) -> np.ndarray:
        """1 - posterior std / prior std."""
        return 1.0 - self.posterior_std / self.prior_std

    @property
    def identifiability(self) -> np.ndarray:
        """1 - posterior variance / prior variance (0: the readings add nothing; 1: they fix it)."""
        return np.clip(1.0 - (self.posterior_std / self.prior_std) ** 2, 0.0, 1.0)

    def as_dict(self, i: int) -> dict:
        return {"prior_std": float(self.prior_std[i]), "prior_source": self.prior_source[i],
                "posterior_std": float(self.posterior_std[i]), "identifiability": float(self.identifiability[i])}


def prior_std(params, p: np.ndarray, limits) -> tuple[np.ndarray, list[str]]:
    """The case's prior std, or the usual range as an uninformed 95 % prior (module docstring)."""
    out, source = np.empty(len(p)), []
    for i in range(len(p)):
        if params.has_prior[i]:
            out[i], _ = params.prior_std[i], source.append("case prior")
            continue
        lo, hi = limits[i].plausible
        if lo > 0 and p[i] > 0:
            out[i] = abs(p[i]) * np.log(hi / lo) / (2 * Z95)
        else:
            out[i] = (hi - lo) / (2 * Z95)
        source.append("usual range")
    return out, source


def prior_posterior(information: np.ndarray, params, p: np.ndarray, limits) -> PriorPosterior:
    """Prior and posterior std of every parameter given the readings' information A'^t A'."""
    s0, source = prior_std(params, p, limits)
    # eqn 55 with the prior C_0 = diag(s0^2): equilibrated, the information spans many decades
    posterior = LinearAnalysis.from_information(np.asarray(information, float) + np.diag(1.0 / s0 ** 2))
    return PriorPosterior(list(params.names), s0, source, posterior.std)
