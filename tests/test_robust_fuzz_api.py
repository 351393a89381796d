"""Fuzz: mutated cases of every kind (one-step elastic, error scales, staged with readings by stage,
forecasts, Mohr-Coulomb) through the Python API (load_case, validate's checks, prepare, identify,
forecast, diagnose, run_case) and a sample through the command line: no traceback, no raw Python or
numpy message, no hang, nothing outside the output folder touched (tests/fuzz_api.py says how).

80 examples in the default suite (small meshes: about 20 s of CPU), 2 000 in the slow one;
the examples are those of the `reproducible` hypothesis profile (tests/conftest.py).
"""
from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings

from fuzz_api import ApiFuzz, mutant

FUZZ = settings(deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                       HealthCheck.data_too_large, HealthCheck.filter_too_much])


@pytest.fixture(scope="module")
def fuzz(tmp_path_factory):
    f = ApiFuzz(tmp_path_factory.mktemp("fuzz-api"), cli_every=50)
    yield f
    f.close()
    print(f"\nAPI fuzz: {f.stats}")


@settings(FUZZ, max_examples=80)
@given(example=mutant())
def test_mutated_cases_through_the_api(example, fuzz):
    fuzz.check(example)


@pytest.mark.slow
@settings(FUZZ, max_examples=2000)
@given(example=mutant())
def test_mutated_cases_through_the_api_long(example, fuzz):
    fuzz.check(example)
