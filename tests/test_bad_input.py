"""Bad input: every mistake in a case file is answered with ONE located line and exit code 2
(`validate` lists every problem the schema and physics checks find, one per line, the first as
the other commands print it).

Each file in tests/data/bad/ is cases/tunnel-paper.yaml with one mistake; its header says what
the answer must contain:

    # expect-line: 10                   line the message must point at
    # expect-field: geometry.axis_depth  field path, printed right after file:line:column
    # expect-reason: not closed          words of the reason (case-insensitive)

The real CLI is run in a subprocess for `validate` (and `run`, when the CLI has it). A
hypothesis property test mutates the valid paper case in-process and checks that whatever the
mutation, geoback either accepts the case or raises a GeobackError located by file and line.
"""
from __future__ import annotations

import copy
import math
import os
import re
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from geoback.case.loading import case_from_data, load_case
from geoback.errors import CaseError, GeobackError
from geoback.inference.identification import prepare

ROOT = Path(__file__).resolve().parents[1]
BAD = ROOT / "tests" / "data" / "bad"
PAPER = ROOT / "cases" / "tunnel-paper.yaml"
BAD_FILES = sorted(BAD.glob("*.yaml"))

# `error: <file>:<line>:<column>: <field>: <message>`
LINE_RE = re.compile(r"^error: (?P<file>.+?):(?P<line>\d+):(?P<column>\d+): (?P<rest>.*)$")


def _cli_commands() -> list[str]:
    """`validate`, plus `run` once the CLI has it."""
    from geoback.commands.cli import app

    names = {c.name or c.callback.__name__ for c in app.registered_commands}
    return [c for c in ("validate", "run") if c in names]


COMMANDS = _cli_commands()


def expectations(path: Path) -> dict[str, str]:
    found = {}
    for line in path.read_text(encoding="utf-8").splitlines()[:10]:
        m = re.match(r"#\s*expect-(line|field|reason):\s*(.+?)\s*$", line)
        if m:
            found[m.group(1)] = m.group(2)
    return found


def _run_cli(command: str, path: Path, workdir: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env.pop("GEOBACK_DEBUG", None)
    env["GEOBACK_CACHE"] = str(workdir / "cache")
    return subprocess.run([sys.executable, "-m", "geoback.commands.cli", command, str(path)], cwd=workdir, env=env,
                          capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="session")
def cli_results(request, tmp_path_factory):
    """Run every selected (file, command) pair at once, in parallel: most of each run is imports."""
    workdir = tmp_path_factory.mktemp("bad-cli")
    wanted = []
    for item in request.session.items:
        params = getattr(getattr(item, "callspec", None), "params", {})
        if item.originalname == "test_bad_case_cli" and "bad" in params:
            wanted.append((params["command"], params["bad"]))
    with ThreadPoolExecutor(max_workers=max(2, min(8, os.cpu_count() or 2))) as pool:
        futures = {key: pool.submit(_run_cli, key[0], key[1], workdir) for key in dict.fromkeys(wanted)}
        results = {key: f.result() for key, f in futures.items()}
    return results, workdir


def test_enough_distinct_bad_cases():
    assert len(BAD_FILES) >= 16
    texts = {p.read_text(encoding="utf-8").split("\n", 5)[-1] for p in BAD_FILES}
    assert len(texts) == len(BAD_FILES), "two bad cases are the same file"
    for p in BAD_FILES:
        assert set(expectations(p)) == {"line", "field", "reason"}, f"{p.name}: header lacks expect-* lines"


def test_paper_case_is_valid():
    """The bad cases are the paper case with one mistake: the paper case itself must pass."""
    loaded = load_case(PAPER)
    prepare(loaded)


@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize("bad", BAD_FILES, ids=lambda p: p.stem)
def test_bad_case_cli(bad: Path, command: str, cli_results):
    results, workdir = cli_results
    proc = results.get((command, bad)) or _run_cli(command, bad, workdir)
    exp = expectations(bad)
    everything = proc.stdout + proc.stderr
    assert "Traceback" not in everything, everything
    assert proc.returncode == 2, f"exit code {proc.returncode}\n{everything}"
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    if command == "validate":  # every problem, one per line, the first as other commands print it
        assert lines, "no message"
        for other in lines[1:]:
            assert LINE_RE.match(other), f"not 'error: file:line:column: ...': {other}"
    else:
        assert len(lines) == 1, f"expected one line on stderr, found {len(lines)}:\n{proc.stderr}"
    assert proc.stdout.strip() == "", proc.stdout
    line = lines[0]
    m = LINE_RE.match(line)
    assert m, f"not 'error: file:line:column: ...': {line}"
    assert Path(m["file"]).name == bad.name, line
    assert int(m["line"]) == int(exp["line"]), f"points at line {m['line']}, expected {exp['line']}: {line}"
    assert m["rest"].startswith(exp["field"] + ": "), f"field {exp['field']!r} not named: {line}"
    assert exp["reason"].lower() in m["rest"].lower(), f"reason {exp['reason']!r} missing: {line}"
    assert "Input should" not in line and "Value error" not in line, line  # pydantic's own wording


def test_no_output_left_behind(cli_results):
    """Rejected cases write nothing (no results/ folder from `run`)."""
    _, workdir = cli_results
    assert not (workdir / "results").exists()


# ---------------------------------------------------------------------------- property test
with open(PAPER, encoding="utf-8") as fh:
    BASE = yaml.safe_load(fh)


def _paths(node, at=()):
    """Every path below the root: (path, value)."""
    if isinstance(node, dict):
        items = node.items()
    elif isinstance(node, list):
        items = enumerate(node)
    else:
        return
    for k, v in items:
        yield at + (k,), v
        yield from _paths(v, at + (k,))


def _get(data, at):
    for part in at:
        data = data[part]
    return data


WRONG = st.one_of(
    st.text(max_size=12),
    st.booleans(),
    st.none(),
    st.integers(min_value=-10**6, max_value=10**6),
    st.floats(allow_nan=True, allow_infinity=True),
    st.lists(st.one_of(st.integers(-5, 5), st.text(max_size=3)), max_size=3),
    st.dictionaries(st.text(max_size=5), st.integers(-5, 5), max_size=2),
    st.sampled_from(["10 MPascal", "-3", "1e999", ".nan", "[1", "E[sand]", "inklinometer", ""]),
)
KEYS = st.one_of(st.sampled_from(["radus", "kind", "name", "E", "readings", "lengths", "x", "top", "K0"]),
                 st.text(alphabet="abcdefghijklmnopqrstuvwxyz_", min_size=1, max_size=10))


def _mutate(data, draw) -> dict:
    """1-3 random mutations; paths are picked with a drawn Random, so every field is as likely."""
    data = copy.deepcopy(data)
    rnd = draw(st.randoms(use_true_random=False))
    for _ in range(draw(st.integers(min_value=1, max_value=3))):
        kind = draw(st.sampled_from(["delete", "replace", "insert", "negate"]))
        paths = [p for p, _ in _paths(data)]
        if kind == "delete" and paths:
            at = rnd.choice(paths)
            del _get(data, at[:-1])[at[-1]]
        elif kind == "replace" and paths:
            leaves = [p for p, v in _paths(data) if not isinstance(v, (dict, list))] or paths
            at = rnd.choice(leaves)
            _get(data, at[:-1])[at[-1]] = draw(WRONG)
        elif kind == "insert":
            maps = [()] + [p for p, v in _paths(data) if isinstance(v, dict)]
            at = rnd.choice(maps)
            _get(data, at)[draw(KEYS)] = draw(WRONG)
        elif kind == "negate":
            numbers = [p for p, v in _paths(data) if isinstance(v, (int, float)) and not isinstance(v, bool)]
            if numbers:
                at = rnd.choice(numbers)
                _get(data, at[:-1])[at[-1]] = -_get(data, at)
    return data


def _check_mutant(data, folder: Path) -> None:
    path = folder / "mutant.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False, allow_unicode=True), encoding="utf-8")
    try:
        loaded = load_case(path)
        prepare(loaded)
    except GeobackError as exc:
        message = str(exc)
        assert "\n" not in message, message
        assert "Input should" not in message and "Value error" not in message, message
        assert re.match(rf"^{re.escape(str(path))}:\d+(:\d+)?: ", message), \
            f"message lacks file:line: {message!r}"


@pytest.fixture(scope="module")
def mutant_folder(tmp_path_factory):
    return tmp_path_factory.mktemp("mutants")


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                   HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_mutated_case_fails_cleanly(data, mutant_folder):
    _check_mutant(_mutate(BASE, data.draw), mutant_folder)


@pytest.mark.slow
@settings(max_examples=1000, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                    HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_mutated_case_fails_cleanly_long(data, mutant_folder):
    _check_mutant(_mutate(BASE, data.draw), mutant_folder)


def test_no_instruments_error_is_located(tmp_path):
    data = copy.deepcopy(BASE)
    data["instruments"] = []
    path = tmp_path / "no-instruments.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    with pytest.raises(GeobackError) as info:
        prepare(load_case(path))
    assert re.match(rf"^{re.escape(str(path))}:\d+:\d+: instruments: ", str(info.value)), str(info.value)


# ---------------------------------------------------------------------------- message details
def _message(data) -> str:
    with pytest.raises(CaseError) as info:
        case_from_data(data, {}, file="x.yaml")
    return info.value.reason


@pytest.mark.parametrize("mutate, words", [
    (lambda d: d["geometry"].update(radius=-3), "expected a number greater than 0, found -3"),
    (lambda d: d["geometry"].update(radius="three"), "expected a number, found 'three'"),
    (lambda d: d["ground"]["layers"][0].update(nu=0.5), "expected a number less than 0.5, found 0.5"),
    (lambda d: d["instruments"][0].update(kind="inklinometer"), "expected one of points, inclinometer"),
    (lambda d: d["instruments"][1].update(start=[1.0]), "expected 2 values [x, y], found a list of 1 item"),
    (lambda d: d["parameters"][0].update(bounds=[1, 2, 3]), "expected 2 values [lower, upper], found 3 values"),
    (lambda d: d.update(name=2024), "expected text, found the number 2024"),
    (lambda d: d["fit"].update(method="newton"), "expected one of 'lm', 'gn' or 'lm-scaled', found 'newton'"),
    (lambda d: d["parameters"][0].update(initial="1e999 kPa"), "expected a finite stress"),
    (lambda d: d["ground"]["layers"][0].update(E=float("inf")), "expected a finite number, found infinity"),
])
def test_messages_say_expected_and_found(mutate, words):
    data = copy.deepcopy(BASE)
    mutate(data)
    assert words in _message(data)


def test_paper_base_is_finite():
    """The property test's base data must itself be valid (and finite)."""
    case = case_from_data(copy.deepcopy(BASE), {}, file="x.yaml")
    assert math.isfinite(case.geometry.radius)
