"""The observational method on a tunnel read on site: dated surveys exported by the instrument
software, a baseline per instrument, an extensometer installed after the advance. Update stage by
stage as an engineer would after the advance and again after the lining, see how the lined surveys
scored against the forecast made before they were read, and read the trigger levels.

The readings were simulated at E = 40 MPa, K0 = 0.7, beta = 0.35 on a mesh twice as fine
(cases/generate_dated_tunnel.py).

    python docs/examples/update_on_site.py [results folder]
"""
import sys
import tempfile
from pathlib import Path

from geoback import identify, load_case, prepare
from geoback.commands.update import update_case

CASE = Path(__file__).resolve().parents[2] / "cases" / "dated-tunnel.yaml"
TRUTH = {"E[clay]": 40_000.0, "K0": 0.7, "beta[advance]": 0.35}
out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp()) / "dated-tunnel-update"

loaded = load_case(CASE)
steps = update_case(loaded, out)  # a joint refit of every survey read by the end of each stage
for step in steps:
    res = step.result
    low, high = res.intervals95()
    print(f"through stage '{step.stage}' ({len(step.surveys)} surveys): " + ", ".join(
        f"{n} = {v:.4g} [{lo:.4g}, {hi:.4g}]" for n, v, lo, hi in zip(res.parameters.names, res.fit.p, low, high)))
    for check in step.checks:  # this stage's surveys against the previous step's forecast
        print("  " + check.sentence())
    if step.sequential is not None:  # the previous posterior as the prior of the new surveys alone
        print("  sequential Bayesian update minus the joint refit: " + ", ".join(
            f"{d:+.2g} std" for d in step.sequential.difference_std))

last = steps[-1]
joint = identify(prepare(loaded))  # the last step is the fit of every survey
print(f"the last step equals the joint fit of all surveys: {abs(last.result.fit.p - joint.fit.p).max():.2g} "
      f"largest difference")
inside = [n for n, (lo, hi) in zip(last.result.parameters.names, zip(*last.result.intervals95()))
          if lo <= TRUTH[n] <= hi]
print(f"truth inside the final 95 % intervals: {', '.join(inside)}")
for t in last.triggers:
    print(f"trigger {t.quantity} ({t.when}): {t.status}")
print(f"every file: {out}")
