"""Fuzz: mutated case files through `geoback validate`.

Whatever the mutation (of the data: fields deleted, replaced, added, negated, mesh sizes from
coarse to absurdly fine; or of the text: characters deleted, lines duplicated, swapped,
re-indented, truncated, YAML syntax, anchors, aliases and merge keys thrown in) validate either
accepts the case or answers with located messages, and never takes more than 5 s or 500 MB:

- no traceback;
- every message names the file and the field: ``file:line:column: field: ...`` (a few messages
  about the file as a whole, e.g. not UTF-8 or too large, cannot name a field; they do not
  arise from these mutations);
- each example validated in a separate interpreter that resets its peak-memory mark before each
  file (tests/measure.py ValidateWorker), so time and memory are per example;
- a sample (one in 20) also through the real command, in a fresh interpreter, timed and
  measured the same way.

200 examples in the default suite, 2 000 in the slow one.
"""
from __future__ import annotations

import math
import os
import re
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from measure import HANG_SECONDS, ValidateWorker, run_cli
from test_bad_input import BASE, _mutate

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "cases" / "tunnel-paper.yaml"
TEXT = PAPER.read_text(encoding="utf-8")
MAX_BYTES = 500e6
CLI_EVERY = 20
# the field: names, [index] and "quoted keys" (which may hold any character but a double quote)
MESSAGE = re.compile(r'^(?P<file>.+?):(?P<line>\d+):(?P<column>\d+): (?P<field>(?:"(?:[^"\\]|\\.)*"|[^:"])+?): '
                     r'(?P<reason>.+)$')

SNIPPETS = ["", " ", "\t", ":", ": ", "- ", "-", "[", "]", "{", "}", ",", "'", '"', "#", "&a ", "*a", "<<: *a\n",
            "? ", "!!python/object:os.system ", "!!binary ", "%YAML 1.1\n", "---\n", "...\n", "\\", "\x00", "\x1b",
            "é", "\u2028", "\ufeff", "1e400", "-0", "0x10", "0o7", ".inf", ".nan", "~", "null", "yes", "no", "1_000",
            "10 MPa", "10MPa", "1e-300", "9" * 40, "2024-01-01", "2024-13-45", "&b [*b]", "kind: points\n", "  ", "\n",
            "\n\n", "!!timestamp ", "!!int ", "!!float ", "!!bool ", "!!set ", "!!omap ", "!!pairs ", "!!str ", "!!map ",
            "!!seq ", "!!null ", "!!merge ", "!!value ", "!foo ", "!<tag:x> ", "|\n", ">-\n"]


@st.composite
def text_mutant(draw) -> str:
    """The paper case's text with 1-4 edits."""
    text = TEXT
    for _ in range(draw(st.integers(1, 4))):
        lines = text.split("\n")
        kind = draw(st.sampled_from(["delete", "insert", "duplicate", "swap", "indent", "truncate", "anchor"]))
        if kind == "delete" and text:
            i = draw(st.integers(0, len(text) - 1))
            text = text[:i] + text[i + draw(st.integers(1, 12)):]
        elif kind == "insert":
            i = draw(st.integers(0, len(text)))
            text = text[:i] + draw(st.one_of(st.sampled_from(SNIPPETS), st.text(max_size=6))) + text[i:]
        elif kind == "duplicate":
            i = draw(st.integers(0, len(lines) - 1))
            lines.insert(i, lines[i])
            text = "\n".join(lines)
        elif kind == "swap" and len(lines) > 1:
            i, j = draw(st.integers(0, len(lines) - 1)), draw(st.integers(0, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
            text = "\n".join(lines)
        elif kind == "indent":
            i = draw(st.integers(0, len(lines) - 1))
            lines[i] = " " * draw(st.integers(0, 6)) + lines[i].lstrip(" ")
            text = "\n".join(lines)
        elif kind == "truncate":
            text = text[:draw(st.integers(0, len(text)))]
        elif kind == "anchor":  # an anchor on one value, aliases (or a merge) elsewhere
            i, j = sorted((draw(st.integers(0, len(lines) - 1)), draw(st.integers(0, len(lines) - 1))))
            head, sep, tail = lines[i].partition(": ")
            if sep:
                lines[i] = f"{head}: &x {tail}"
                h2, sep2, _ = lines[j].partition(": ")
                lines[j] = f"{h2}: *x" if sep2 and j != i else lines[j] + "\n<<: *x"
            text = "\n".join(lines)
    return text


@st.composite
def data_mutant(draw) -> str:
    """The paper case's data with 1-3 field mutations, and sometimes mesh sizes from coarse to
    absurdly fine (around and far beyond the size limit)."""
    data = _mutate(BASE, draw)
    if draw(st.booleans()) and isinstance(data.get("geometry"), dict):
        mesh = {}
        radius = BASE["geometry"]["radius"]
        for field in draw(st.sets(st.sampled_from(["size_tunnel", "size_far", "size_instruments", "growth"]))):
            if field == "growth":
                mesh[field] = draw(st.floats(0.011, 2.0))
            else:
                mesh[field] = radius * 10 ** draw(st.floats(-4.2, 1.0))
        data["mesh"] = mesh
    return yaml.safe_dump(data, sort_keys=False, allow_unicode=True)


MUTANTS = st.one_of(text_mutant(), data_mutant())


def check_message(message: str, path: Path) -> None:
    assert "\n" not in message, message
    assert "Traceback" not in message and "Input should" not in message and "Value error" not in message, message
    m = MESSAGE.match(message)
    assert m, f"message lacks file:line:column: field: {message!r}"
    assert Path(m["file"]) == path, message


class Fuzz:
    def __init__(self, folder: Path):
        self.folder = folder
        self.env = dict(os.environ, GEOBACK_CACHE=str(folder / "cache"))
        self.env.pop("GEOBACK_DEBUG", None)
        self.env.pop("GEOBACK_MAX_DOFS", None)
        self.worker = ValidateWorker(self.env)
        self.count = 0
        self.stats = {"accepted": 0, "refused": 0, "cli": 0, "max_seconds": 0.0, "max_bytes": 0.0,
                      "cli_max_seconds": 0.0, "cli_max_bytes": 0.0}

    def check(self, text: str) -> None:
        self.count += 1
        path = self.folder / f"mutant{self.count % 2}.yaml"
        path.write_bytes(text.encode("utf-8", errors="replace"))
        out = self.worker.validate(path)
        assert out["traceback"] is None, out["traceback"]
        assert out["seconds"] < HANG_SECONDS, f"validate hung ({out['seconds']:.0f} s):\n{text}"
        assert not out["peak_bytes"] > MAX_BYTES, f"validate peaked at {out['peak_bytes'] / 1e6:.0f} MB:\n{text}"
        self.stats["max_seconds"] = max(self.stats["max_seconds"], out["seconds"])
        if not math.isnan(out["peak_bytes"]):
            self.stats["max_bytes"] = max(self.stats["max_bytes"], out["peak_bytes"])
        if out["ok"]:
            self.stats["accepted"] += 1
        else:
            self.stats["refused"] += 1
            for message in out["messages"]:
                check_message(message, path)
        if self.count % CLI_EVERY == 0:
            self.cli(path, out)

    def cli(self, path: Path, library: dict) -> None:
        run = run_cli(["validate", path], self.folder, env=self.env)
        self.stats["cli"] += 1
        everything = run.stdout + run.stderr
        assert "Traceback" not in everything, everything
        assert run.returncode == (0 if library["ok"] else 2), everything
        assert run.seconds < HANG_SECONDS, f"geoback validate hung ({run.seconds:.0f} s)"
        assert not run.peak_bytes > MAX_BYTES, f"geoback validate peaked at {run.peak_bytes / 1e6:.0f} MB"
        self.stats["cli_max_seconds"] = max(self.stats["cli_max_seconds"], run.seconds)
        if not math.isnan(run.peak_bytes):
            self.stats["cli_max_bytes"] = max(self.stats["cli_max_bytes"], run.peak_bytes)
        if not library["ok"]:
            lines = [line.removeprefix("error: ") for line in run.stderr.splitlines() if line.strip()]
            notices = [line for line in lines if line.startswith("notice: ")]
            lines = [line for line in lines if not line.startswith("notice: ")]
            assert lines == library["messages"], (lines, library["messages"])
            del notices

    def close(self) -> None:
        self.worker.close()


@pytest.fixture(scope="module")
def fuzz(tmp_path_factory):
    f = Fuzz(tmp_path_factory.mktemp("fuzz"))
    yield f
    f.close()
    print(f"\nfuzz: {f.count} examples, {f.stats}")


FUZZ = settings(deadline=None, database=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                       HealthCheck.data_too_large, HealthCheck.filter_too_much])


@settings(FUZZ, max_examples=200)
@given(text=MUTANTS)
def test_mutated_case_files_through_validate(text, fuzz):
    fuzz.check(text)


@pytest.mark.slow
@settings(FUZZ, max_examples=2000, derandomize=False)
@given(text=MUTANTS)
def test_mutated_case_files_through_validate_long(text, fuzz):
    fuzz.check(text)
