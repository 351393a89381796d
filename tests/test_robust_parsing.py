"""Bounded work while parsing: alias bombs, merge bombs, deep nesting, huge files are refused
at once with a located message; legitimate anchors, aliases and merge keys keep working."""
from __future__ import annotations

import re
import time
import tracemalloc
from pathlib import Path

import pytest

from geoback.case import yamlmarks
from geoback.case.loading import load_case
from geoback.errors import CaseError
from geoback.case.yamlmarks import parse_yaml_with_marks
from measure import HANG_SECONDS, run_cli

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "cases" / "tunnel-paper.yaml"
BAD = ROOT / "tests" / "data" / "bad"
LOCATED = re.compile(r"^(?P<file>.+?):(?P<line>\d+):(?P<column>\d+): (?P<field>[^:]+): expected ")


def alias_bomb(levels: int, width: int = 9) -> str:
    """The classic 'billion laughs': each anchor is a list of `width` aliases of the previous one."""
    lines = ['a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    names = [chr(ord("a") + i) for i in range(levels)]
    for prev, name in zip(names, names[1:]):
        lines.append(f"{name}: &{name} [" + ", ".join([f"*{prev}"] * width) + "]")
    return "\n".join(lines) + "\n"


def merge_bomb(levels: int) -> str:
    lines = ["m0: &m0 {k0: 1, k1: 2, k2: 3, k3: 4}"]
    for i in range(1, levels):
        lines.append(f"m{i}: &m{i} {{<<: [*m{i - 1}, *m{i - 1}, *m{i - 1}], x{i}: 1}}")
    return "\n".join(lines) + "\n"


def refused_quickly(text: str, tmp_path: Path, name: str = "bomb.yaml") -> CaseError:
    """Refused without expanding (allocating under 30 MB; no hang), with a located 'expected ... found' message."""
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    t0 = time.perf_counter()
    with pytest.raises(CaseError) as info:
        load_case(path)
    seconds = time.perf_counter() - t0
    assert seconds < HANG_SECONDS, f"hung: {seconds:.0f} s"
    tracemalloc.start()  # (slows Python down: timed above, without it)
    try:
        with pytest.raises(CaseError):
            load_case(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 30e6, f"allocated {peak / 1e6:.0f} MB"
    message = str(info.value)
    assert "\n" not in message
    assert LOCATED.match(message), message
    assert Path(LOCATED.match(message)["file"]) == path
    return info.value


def test_billion_laughs_is_refused_at_once(tmp_path):
    text = alias_bomb(9)
    assert len(text.encode()) < 450  # the 413-byte bomb of the issue, give or take the spacing
    err = refused_quickly(text, tmp_path)
    assert "alias" in err.reason and "found them expanding" in err.reason


@pytest.mark.parametrize("levels", [5, 12, 20])
def test_deeper_and_shallower_alias_bombs(tmp_path, levels):
    refused_quickly(alias_bomb(levels), tmp_path)


def test_merge_key_bomb(tmp_path):
    err = refused_quickly(merge_bomb(40), tmp_path)
    assert "merge" in err.reason


@pytest.mark.parametrize("text", ["name: " + "[" * 5000 + "]" * 5000 + "\n",
                                  "name: " + "{a: " * 300 + "1" + "}" * 300 + "\n",
                                  "name:\n" + "".join("  " * i + "- \n" for i in range(1, 200))])
def test_deep_nesting(tmp_path, text):
    err = refused_quickly(text, tmp_path)
    assert "levels of nested" in err.reason or "invalid YAML" in err.reason


def test_too_many_values(tmp_path):
    text = "name: x\nreadings: [" + ", ".join(["1"] * (yamlmarks.MAX_NODES + 10)) + "]\n"
    err = refused_quickly(text, tmp_path)
    assert err.line == 2 and "values in a case file" in err.reason


def test_huge_file_is_refused_before_parsing(tmp_path):
    path = tmp_path / "huge.yaml"
    with open(path, "w") as fh:
        fh.write("name: x\n# " + "c" * (4 * yamlmarks.MAX_BYTES) + "\n")  # read up to the limit only
    tracemalloc.start()
    try:
        with pytest.raises(CaseError) as info:
            load_case(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < yamlmarks.MAX_BYTES + 1e6, f"allocated {peak / 1e6:.0f} MB for a file it refuses by its size"
    assert str(info.value).startswith(f"{path}: expected a case file of at most")


def test_alias_bomb_through_the_cli(tmp_path):
    """The real command: refused with a few MB beyond the interpreter (the time: benchmarks/command_times.py)."""
    path = tmp_path / "bomb.yaml"
    path.write_text(alias_bomb(9), encoding="utf-8")
    run = run_cli(["validate", path], tmp_path)
    assert run.returncode == 2, run.stderr
    assert run.stderr.startswith(f"error: {path}:1:"), run.stderr
    assert "Traceback" not in run.stderr
    assert not run.peak_bytes > 150e6, f"{run.peak_bytes / 1e6:.0f} MB"


# ---------------------------------------------------------------------------- legitimate YAML
MERGED = """\
name: merged
geometry: {radius: 3.0, axis_depth: 10.0, width: 40.0, depth: 30.0}
ground:
  unit_weight: 20.0
  K0: 1.0
  layers:
    - {name: clay, top: 0.0, E: 10 MPa, nu: 0.49}
mesh: {size_tunnel: 0.4, size_far: 4.0}
instruments:
  - &X1
    name: X1
    kind: extensometer
    start: &surface [0.0, 0.0]
    end: [0.0, -6.5]
    spacing: 1.25
    stations: 5
    sigma: 0.0005
    var_a: 1.0e-6
  - <<: *X1
    name: X2
    sigma: 0.001          # overrides the merged value
    end: [2.0, -6.5]
  - <<: [{name: X3, end: [4.0, -6.5]}, *X1]
    start: *surface
parameters:
  - {name: E, initial: 5 MPa, bounds: [100, 1.0e6]}
"""


def test_merge_keys_and_aliases_work(tmp_path):
    data, marks = parse_yaml_with_marks(MERGED, "m.yaml")
    # the YAML merge-key specification (yaml.org/type/merge): keys written in the mapping override
    # merged ones, and in a sequence of merged mappings the earlier one wins (`<<: [{name: X3}, *X1]`
    # gives X3). Written out here, not taken from a YAML library: PyYAML 6.0.4 resolves that
    # sequence to X1, 6.0.2 to X3; the reference is the specification, not a library version.
    x1 = {"name": "X1", "kind": "extensometer", "start": [0.0, 0.0], "end": [0.0, -6.5], "spacing": 1.25,
          "stations": 5, "sigma": 0.0005, "var_a": 1.0e-6}
    assert data == {
        "name": "merged",
        "geometry": {"radius": 3.0, "axis_depth": 10.0, "width": 40.0, "depth": 30.0},
        "ground": {"unit_weight": 20.0, "K0": 1.0,
                   "layers": [{"name": "clay", "top": 0.0, "E": "10 MPa", "nu": 0.49}]},
        "mesh": {"size_tunnel": 0.4, "size_far": 4.0},
        "instruments": [x1, {**x1, "name": "X2", "sigma": 0.001, "end": [2.0, -6.5]},
                        {**x1, "name": "X3", "end": [4.0, -6.5]}],
        "parameters": [{"name": "E", "initial": "5 MPa", "bounds": [100, "1.0e6"]}],  # YAML 1.1: no exponent sign, a string
    }
    x1, x2, x3 = data["instruments"]
    assert x1["sigma"] == 0.0005 and x2["sigma"] == 0.001 and x2["stations"] == 5
    assert x3["name"] == "X3" and x3["end"] == [4.0, -6.5] and x3["sigma"] == 0.0005
    lines = MERGED.splitlines()
    assert marks[("instruments", 1, "sigma")][0] == lines.index("    sigma: 0.001          # overrides the merged value") + 1
    assert marks[("instruments", 1, "spacing")][0] == lines.index("    spacing: 1.25") + 1  # where it is written
    path = tmp_path / "merged.yaml"
    path.write_text(MERGED)
    case = load_case(path).case
    assert [i.name for i in case.instruments] == ["X1", "X2", "X3"]
    assert case.instruments[1].sigma == 0.001 and case.instruments[1].stations == 5
    assert case.instruments[2].start == (0.0, 0.0)


def test_duplicate_keys_are_still_refused_next_to_merges():
    text = "base: &b {a: 1}\nx:\n  <<: *b\n  c: 1\n  c: 2\n"
    with pytest.raises(CaseError) as info:
        parse_yaml_with_marks(text, "d.yaml")
    assert str(info.value).startswith("d.yaml:5:3: x.c: duplicate key 'c'")


@pytest.mark.parametrize("text, words", [("x:\n  <<: 3\n", "expected a mapping"),
                                         ("x:\n  <<: [[1]]\n", "expected a mapping"),
                                         ("x: &x\n  <<: *x\n", "invalid YAML")])
def test_bad_merges_are_located(text, words):
    with pytest.raises(CaseError) as info:
        parse_yaml_with_marks(text, "m.yaml")
    assert str(info.value).startswith("m.yaml:") and words in str(info.value)


@pytest.mark.parametrize("path", [PAPER] + sorted(BAD.glob("*.yaml")), ids=lambda p: p.name)
def test_fast_and_pure_python_parsers_agree(path, monkeypatch):
    """libyaml feeds the composer when available; its values, marks and messages are pyyaml's."""
    text = path.read_text(encoding="utf-8")

    def outcome():
        try:
            return parse_yaml_with_marks(text, "f.yaml")
        except CaseError as exc:
            return str(exc)

    fast = outcome()
    monkeypatch.setattr(yamlmarks, "_CLoader", None)
    assert outcome() == fast


ODD = ["\t", "a: 1\n---\nb: 2\n", "a: &x 1\nb: *y\n", "%YAML 1.1\n%YAML 1.1\n---\na: 1\n", "@a: 1", "a: \x00",
       "x:\n  y: 1\n  z: \x07\n", "a: !!timestamp x\n", "a: !!int x\n", "a: !!float x\n", "!!timestamp x: 1\n",
       "a: !!pairs 3\n", "a: !!bool maybe\n", "a: !!merge x\n", "<<: 1\n", "a: !!value x\n", "x:\n  y: &z 1\n  w: *q\n",
       "a: !!python/name:os.system\n", "a: 2001-13-45\n", "? [1]\n: 2\n", "a: |\n  x\n b: 1", "{", "", "a: `x`"]


@pytest.mark.parametrize("text", ODD, ids=[repr(t)[:24] for t in ODD])
def test_odd_yaml_gets_a_located_message_with_a_field(text):
    """Syntax, composer and constructor errors (pyyaml raises plain AttributeError/ValueError for
    some tagged values) all end as 'file:line:column: field: ...'."""
    with pytest.raises(CaseError) as info:
        parse_yaml_with_marks(text, "odd.yaml")
    assert re.match(r"^odd\.yaml:\d+:\d+: [^:]+: ", str(info.value)), str(info.value)
