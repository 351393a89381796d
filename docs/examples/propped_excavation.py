"""A propped deep excavation: identify both clays' stiffness, K0 and the upper props' stiffness from the
wall inclinometer, the settlement points and the prop load cells read after the first two lifts, then
forecast the final lift to formation and compare the forecast with what the truth would read.

The readings were simulated at known values on a mesh twice as fine (cases/generate_propped_excavation.py:
E[soft] = 25 MPa, E[stiff] = 90 MPa, K0 = 0.9, k[P1] = 35 MN/m/m, half the design value); here the same
truth is run for the final lift (no noise) to see whether the forecast bands hold it.

    python docs/examples/propped_excavation.py
"""
from pathlib import Path

import numpy as np

from geoback import identify, load_case, prepare
from geoback.commands.simulate import without_readings
from geoback.inference.synthetic import synthetic_readings
from geoback.worth.forecast import forecast

CASE = Path(__file__).resolve().parents[2] / "cases" / "propped-excavation.yaml"
TRUTH = {"E[soft]": 25_000.0, "E[stiff]": 90_000.0, "K0": 0.9, "k[P1]": 35_000.0}

analysis = prepare(load_case(CASE))
sim = analysis.simulation
print(f"stages {', '.join(sim.stages)}; {sim.dofs} DOFs")
result = identify(analysis)  # exact sensitivities through every lift, prop and preload
for p, true in TRUTH.items():
    r = result[p]
    scale = 1.0 if p == "K0" else 1e-3  # moduli in MPa, stiffness in MN/m/m
    inside = "inside" if r.low <= true <= r.high else "OUTSIDE"
    print(f"  {p} = {r.value * scale:.4g} ± {r.std * scale:.2g} (95 % {r.low * scale:.4g} to {r.high * scale:.4g}); "
          f"truth {true * scale:g}: {inside} the interval")

fc = forecast(analysis, result)  # the final lift, with 95 % bands from C_p
truth = synthetic_readings(without_readings(CASE), refine=2.0, values=TRUTH, by_stage=True)
wall = fc.rows("wall-deflection")
true_wall = truth["I1"]["lift3"]
held = np.mean((fc.low[wall] <= true_wall) & (true_wall <= fc.high[wall]))
k = wall[np.argmax(np.abs(fc.value[wall]))]
print(f"wall deflection after the final lift: largest {1e3 * abs(fc.value[k]):.1f} mm "
      f"(95 % {1e3 * abs(fc.high[k]):.1f} to {1e3 * abs(fc.low[k]):.1f} mm); the truth inside the band at "
      f"{100 * held:.0f} % of the stations")
prop = fc.rows("prop-force-level-2")[0]
true_prop = float(truth["LC2"]["lift3"][0])
print(f"level-2 prop force after the final lift: {fc.value[prop]:.0f} kN per prop (95 % {fc.low[prop]:.0f} to "
      f"{fc.high[prop]:.0f} kN); the truth {true_prop:.0f} kN")
