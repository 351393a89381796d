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


@pytest.mark.slow
def test_a_lost_preload_is_named_with_an_interval_from_no_preload():
    """The level-2 props lost their preload at lock-off (0 for 50 kN/m). The truth lies at the preload's natural
    limit, so the estimate is near 0 and its 95 % interval reaches 0: a finding (the readings bound it above and
    exclude the assumed 50 kN/m), not an end the readings leave open - the cause is named (check 4 failed it
    before, as 'reaches a limit the readings do not move it from', and called it tentative for its relative error)."""
    d = diagnose(load_case(CONCEALED / "excavation-preload-lost.yaml"))
    assert not d.adequate_before and d.adequate_after
    assert [s.hypothesis.key for s in d.accepted] == ["preload-lost[P2]"]
    assert d.grade == "named" and d.accepted[0].checks["determined"].passed
    (name, v, sd, lo, hi), = d.estimates(d.accepted[0])
    assert name == "preload[P2]" and lo == 0.0 and 0.0 <= v < hi < 10.0  # kN/m: the 50 assumed far outside
    assert d.open_ends(name) == (False, False)
