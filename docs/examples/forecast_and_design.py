"""From back-analysis to forecast: readings of the first stage, the lined stage forecast with its
95 % band, what the readings tell about each parameter, and where one more instrument pays off.

    python docs/examples/forecast_and_design.py
"""
from pathlib import Path

import numpy as np

from geoback import identify, load_case, prepare
from geoback.worth.design import design
from geoback.worth.forecast import forecast

CASE = Path(__file__).resolve().parents[2] / "cases" / "staged-forecast.yaml"

analysis = prepare(load_case(CASE))
result = identify(analysis)
print(result)

pp = result.prior_posterior  # prior -> posterior std, identifiability 0..1
for name, ident in zip(pp.names, pp.identifiability):
    print(f"{name}: identifiability {ident:.2f}")

fc = forecast(analysis, result)  # the case's forecasts at the estimate, band and sampling check
rows = fc.rows("trough")
i = rows[np.argmax(np.abs(fc.value[rows]))]
print(f"largest settlement after the lined stage: {-1e3 * fc.value[i]:.2f} mm "
      f"(95 % {-1e3 * fc.high[i]:.2f} to {-1e3 * fc.low[i]:.2f} mm), "
      f"P(> {1e3 * fc.alert[i]:.0f} mm) = {100 * fc.p_exceed[i]:.2g} %")

d = design(analysis, result)  # rank the candidate instruments of the case's design section
k = d.ranking[0]
print(f"best next instrument: {d.best} - the trough's std {1e3 * d.before:.3f} -> {1e3 * d.after[k]:.3f} mm")
