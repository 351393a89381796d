"""Repeat the paper case's identification on many noisy copies of its readings (noise drawn from
each instrument's C_x) and compare the scatter of the estimates with the C_p geoback reports.

    python docs/examples/monte_carlo.py [replicates]
"""
import sys
from pathlib import Path

import numpy as np

from geoback import load_case, prepare
from geoback.inference.identification import identify, identify_replicates

CASE = Path(__file__).resolve().parents[2] / "cases" / "tunnel-paper.yaml"
N = int(sys.argv[1]) if len(sys.argv) > 1 else 200

analysis = prepare(load_case(CASE))
clean = analysis.misfit.data.measured  # the case's readings (a finer mesh, no noise)
rng = np.random.default_rng(1)
noisy = np.array([clean + analysis.misfit.data.noise(rng) for _ in range(N)])
rep = identify_replicates(analysis, noisy)  # one simulation, one factorisation for all of them

cp = identify(analysis).reliability.covariance
print(f"{N} replicates, {rep.converged.sum()} converged, "
      f"{analysis.simulation.counters.factorisations} factorisation(s) in all")
for i, name in enumerate(rep.names):
    print(f"{name}: sample std {rep.p[:, i].std(ddof=1):.4g}, C_p std {np.sqrt(cp[i, i]):.4g}")
