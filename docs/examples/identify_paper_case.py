"""The library's front door on the paper's tunnel: load a case, identify its parameters, read the
result, ask what the model may be missing.

    python docs/examples/identify_paper_case.py
"""
from pathlib import Path

from geoback import diagnose, identify, load_case, prepare

CASE = Path(__file__).resolve().parents[2] / "cases" / "tunnel-paper.yaml"

loaded = load_case(CASE)
analysis = prepare(loaded)  # mesh (cached), FE model, instruments, readings
result = identify(analysis)  # Levenberg-Marquardt with exact sensitivities, then C_p, SVD, Q
print(result)  # status, chi2/dof and every parameter with its std and 95 % interval

E = result["E[clay]"]
print(f"E = {E.value / 1000:.2f} MPa ± {E.std / 1000:.2f} MPa (95 % {E.low / 1000:.2f}-{E.high / 1000:.2f} MPa)")
print(f"correlation of E and K0: {result.reliability.correlation[0, 1]:+.2f}")
print(f"factorisations for the whole fit: {result.counts['factorisations']}")

d = diagnose(analysis)  # reuses the prepared case and its factorisation
print("model adequate:", d.adequate_before, "| missing:", [s.hypothesis.title for s in d.accepted] or "nothing")
