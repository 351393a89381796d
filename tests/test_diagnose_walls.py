"""`geoback diagnose` on a propped excavation (cases/concealed/generate_excavation.py): the library's rows for
walls and supports (a cracked wall, a slack prop level, a preload lost) are proposed where they apply, and a
concealed one is named, estimated (its interval holding the truth) and fixes the fit. The benchmark
benchmarks/diagnosis_excavation.py measures all six concealed excavation cases."""
import numpy as np
import pytest

from conftest import CASES
from geoback.case.loading import load_case
from geoback.diagnosis import diagnose
from geoback.diagnosis.hypotheses import candidate_hypotheses
from geoback.inference.identification import prepare

CONCEALED = CASES / "concealed"


@pytest.mark.quick
def test_wall_and_support_hypotheses_are_proposed_where_they_apply():
    """Every wall's E, every prop's stiffness, and the preload of a prop that has one (not of one that has none)."""
    a = prepare(load_case(CONCEALED / "excavation-null.yaml"))
    keys = {h.key: h for h in candidate_hypotheses(a.misfit, a.parameters.initial)}
    assert {"wall-stiffness[wall]", "support-stiffness[P1]", "support-stiffness[P2]", "preload-lost[P2]"} <= set(keys)
    assert "preload-lost[P1]" not in keys  # P1 has no preload to lose
    h = keys["support-stiffness[P1]"]
    assert h.names == ["k[P1]"] and h.parameters[0].initial == pytest.approx(70_000.0)
    assert h.cause == "ground"


@pytest.mark.slow
def test_a_slack_prop_level_is_named_and_its_stiffness_recovered():
    """The capping-beam struts take load at a sixth of their design stiffness (k[P1] = 12 MN/m/m for 70)."""
    d = diagnose(load_case(CONCEALED / "excavation-support-stiffness.yaml"))
    assert not d.adequate_before
    assert [s.hypothesis.key for s in d.accepted] == ["support-stiffness[P1]"]
    assert d.grade == "named"  # it passes the claim checks: no rival of another family explains the readings
    rel = d.final_reliability
    lo, hi = rel.interval95()
    i = rel.names.index("k[P1]")
    assert lo[i] <= 12_000.0 <= hi[i]
    assert d.adequate_after and rel.reduced_chi2 < d.baseline_reliability.reduced_chi2
    assert d.causes["ground"] and not d.causes["instrument"]
