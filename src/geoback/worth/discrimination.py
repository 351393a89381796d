"""Which candidate instrument would tell two fitted hypotheses apart (issue 13.3: data worth for
model discrimination, beside `design.py`'s data worth for forecasts and parameters).

Two hypotheses a and b are fitted to the same readings (estimates p_a, p_b; computed readings x_a,
x_b). If a is true, a candidate c read with covariance C_x,c would on average read x_a,c, and b,
refitted to all the readings, keeps a misfit it cannot remove. Linearised about b's estimate, with
r the whitened difference x_a - x_b over the existing readings and the candidate's together and B
b's whitened sensitivities there (its prior rows included),

    lambda_ab(c) = || (I - B B^+) r ||^2  -  || (I - B_0 B_0^+) r_0 ||^2

is the growth of b's chi-square when c's readings join (subscript 0: the existing readings alone):
the non-centrality of the likelihood-ratio statistic that c adds against b (Atkinson & Fedorov
1975, T-optimum designs for discriminating between models). Either hypothesis may be the true one,
so a candidate's separation is the smaller of lambda_ab and lambda_ba, and its power the
probability that a chi^2(1) test at `level` then rejects the wrong one,
P(chi'^2(1, lambda) > chi^2_1(1 - level)). Like `design.py` it is linear about the fits and needs
no readings of the candidates, only where they are and how accurate they are (C_x,c with its
integration constants; the candidates' rows whitened by the seam, ``misfit.whiten_block``); it
ignores the noise of the existing readings, which both fits share.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geoback.inference.misfit import whiten_block
from geoback.physics.simulation import is_constant


@dataclass(frozen=True)
class Discrimination:
    a: str  # the two hypotheses, in words
    b: str
    names: list[str]  # the candidates
    lam_ab: np.ndarray  # b's chi-square growth from each candidate if a is true
    lam_ba: np.ndarray  # a's if b is true
    level: float

    @classmethod
    def nothing(cls, level: float = 0.05) -> "Discrimination":
        """The diagnosis refitted no hypothesis: nothing to tell apart."""
        return cls("", "", [], np.zeros(0), np.zeros(0), level)

    @property
    def found(self) -> bool:
        return bool(self.names)

    @property
    def separation(self) -> np.ndarray:
        """The non-centrality a candidate guarantees whichever hypothesis is true."""
        return np.minimum(self.lam_ab, self.lam_ba)

    @property
    def power(self) -> np.ndarray:
        """Probability that a chi^2(1) test at `level` rejects the wrong hypothesis after the candidate."""
        from scipy import stats

        return stats.ncx2.sf(stats.chi2.isf(self.level, 1), 1, np.maximum(self.separation, 1e-12))

    def as_dict(self) -> dict:
        return {"a": self.a, "b": self.b, "level": self.level,
                "candidates": [{"name": n, "lambda_ab": float(x), "lambda_ba": float(y), "separation": float(s),
                                "power": float(w)}
                               for n, x, y, s, w in zip(self.names, self.lam_ab, self.lam_ba, self.separation,
                                                        self.power)]}


@dataclass(frozen=True)
class _Fitted:
    """One hypothesis at its estimate: computed readings and whitened sensitivities, existing
    readings and each candidate's."""

    x0: np.ndarray  # computed existing readings
    B0: np.ndarray  # whitened sensitivities of the existing readings, then the prior rows
    xc: list  # computed readings of each candidate
    Bc: list  # their whitened sensitivities


def _fitted(misfit, p, cands) -> _Fitted:
    ev = misfit.evaluate(p, jacobian=True)
    B0 = np.vstack([misfit.whiten(ev.A), ev.B[ev.m:]])
    names = list(misfit.parameters.names)
    cols = [j for j, n in enumerate(names) if not is_constant(n)]
    physical = [names[j] for j in cols]
    values = {k: v for k, v in misfit.values(p).items() if not is_constant(k)}
    sim = misfit.simulation
    xc, Bc = [], []
    for block in cands:
        with sim.surveying([block]) as view:
            pred = view.predict(values, physical, sensitivities=True)
        A = np.zeros((block.m, len(names)))
        A[:, cols] = pred.A
        xc.append(pred.x)
        Bc.append(whiten_block(block, A))
    return _Fitted(ev.x, B0, xc, Bc)


def _unexplained(B: np.ndarray, r: np.ndarray) -> float:
    """|| (I - B B^+) r ||^2, with B's columns equilibrated (moduli beside ratios)."""
    s = np.linalg.norm(B, axis=0)
    s = np.where(s > 0, s, 1.0)
    coef, *_ = np.linalg.lstsq(B / s, r, rcond=1e-12)
    e = r - (B / s) @ coef
    return float(e @ e)


def _growth(truth: _Fitted, other: _Fitted, misfit, blocks) -> np.ndarray:
    """chi-square growth of `other` refitted when each candidate's readings join, `truth` true."""
    d0 = misfit.whiten(truth.x0 - other.x0)
    r0 = np.concatenate([d0, np.zeros(other.B0.shape[0] - len(d0))])
    base = _unexplained(other.B0, r0)
    out = []
    for k, block in enumerate(blocks):
        dc = whiten_block(block, truth.xc[k] - other.xc[k])
        # the candidate's rows go beside the existing readings' (before the prior rows: order is immaterial)
        r = np.concatenate([r0, dc])
        B = np.vstack([other.B0, other.Bc[k]])
        out.append(max(_unexplained(B, r) - base, 0.0))
    return np.array(out)


def discriminate(a, b, blocks, names: list[str], level: float = 0.05) -> Discrimination:
    """Separation and power of each candidate (`blocks`: InstrumentBlocks at their stage; `names`)
    between hypotheses a and b, each given as (words, misfit, estimate p)."""
    (wa, ma, pa), (wb, mb, pb) = a, b
    fa, fb = _fitted(ma, pa, blocks), _fitted(mb, pb, blocks)
    return Discrimination(wa, wb, list(names), _growth(fa, fb, mb, blocks), _growth(fb, fa, ma, blocks), level)


def leading_pair(diagnosis, analysis):
    """The two hypotheses that explain the readings best in `diagnosis`'s first round, each as
    (words, misfit, estimate): the accepted cause and its rival of another family when it was not
    singled out, else the two refitted hypotheses of lowest AIC, or the one refitted
    and the case's model without it; None when no hypothesis was refitted."""
    first = diagnosis.rounds[0]
    fitted = sorted((s for s in first.ranking if s.refit is not None and s.misfit is not None
                     and np.isfinite(s.aic)), key=lambda s: s.aic)
    acc = first.accepted
    if acc is not None and getattr(acc, "rivals", None):  # not singled out: the cause and its rival of
        fitted = [acc, acc.rivals[0]]  # another family (diagnosis/claims.py)
    pair = [(s.hypothesis.title, s.misfit, s.refit.p) for s in fitted[:2]]
    if not pair:
        return None
    if len(pair) == 1:
        pair.append(("the case's model as it is", analysis.misfit, diagnosis.baseline.fit.p))
    return tuple(pair)
