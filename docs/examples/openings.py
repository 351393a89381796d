"""Sections with openings: a horseshoe tunnel dug as top heading and bench, and twin tunnels in a full
model. Identify each case's parameters from readings simulated at known values on a mesh twice as
fine (cases/generate_natm_heading_bench.py, cases/generate_twin_tunnels.py) and compare.

    python docs/examples/openings.py
"""
from pathlib import Path

from geoback import identify, load_case, prepare

CASES = Path(__file__).resolve().parents[2] / "cases"
TRUTH = {"natm-heading-bench": {"E[clay]": 60_000.0, "K0": 0.8, "beta[heading]": 0.35},
         "twin-tunnels": {"E[clay]": 45_000.0, "K0": 0.65}}

results = {}
for name, truth in TRUTH.items():
    analysis = prepare(load_case(CASES / f"{name}.yaml"))  # meshed inside its openings (parts, linings' bands)
    print(f"{name}: stages {', '.join(analysis.simulation.stages)}; {analysis.simulation.dofs} DOFs")
    result = identify(analysis)  # exact sensitivities through every stage's removal and installation
    results[name] = result
    for p, true in truth.items():
        r = result[p]
        scale = 1e-3 if p.startswith("E[") else 1.0  # moduli in MPa
        inside = "inside" if r.low <= true <= r.high else "OUTSIDE"
        print(f"  {p} = {r.value * scale:.4g} ± {r.std * scale:.2g} (95 % {r.low * scale:.4g} to {r.high * scale:.4g}); "
              f"truth {true * scale:g}: {inside} the interval")
