"""The fuzzer of the Python API and the commands (tests/test_robust_fuzz_api.py): mutated cases of
every kind the shipped cases show (one-step elastic, error scales, staged with a lining and
readings by stage, forecasts, Mohr-Coulomb ground), through ``geoback.load_case``, validate's
library path, ``prepare``, ``identify``, ``forecast``, ``diagnose`` and ``run_case`` in a long-lived
worker interpreter, and a sample through the real command line.

What is checked, whatever the mutation:
- no traceback, no raw Python or numpy message (``RAW``), no Python warning (a numpy
  RuntimeWarning is a raw message on stderr);
- an answer within ``measure.HANG_SECONDS`` (the worker is killed and the example reported if not);
- nothing outside the output folder touched: the working folder (the worker's and the command's
  current folder, holding the case file and its readings) keeps its identity (device, inode) and
  every file's size and modification time, the shipped cases too.

Meshes are kept small (the API's cost is then a fraction of a second an example; a mutation that
asks for a finer mesh is kept above a floor): the fuzzer looks for wrong answers to odd input, not
for the cost of fine meshes (``test_robust_mesh.py``, ``test_robust_budget.py``).
"""
from __future__ import annotations

import copy
import json
import math
import os
import random
import re
import select
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml
from hypothesis import strategies as st

from measure import HANG_SECONDS, run_cli
from test_bad_input import _get, _paths

ROOT = Path(__file__).resolve().parents[1]
CASES = ROOT / "cases"

# base cases: (file, readings files it names)
BASES = {
    "elastic": ("tunnel-paper.yaml", []),
    "scales": ("tunnel-paper-error-scales.yaml", []),
    "staged": ("staged-tunnel.yaml", ["staged-tunnel-readings.csv"]),
    "forecast": ("staged-forecast.yaml", ["staged-forecast-readings.csv"]),
    "plastic": ("plastic-tunnel.yaml", ["plastic-tunnel-readings.csv"]),
}
# coarse meshes (fractions of the radius; far size a fraction of the domain): a fraction of a second a fit
COARSE = {"size_tunnel": 0.5, "far": 0.2}
FINEST = 0.25  # a mutated size_tunnel is kept at or above this fraction of the radius
# the commands' time limit in the fuzzer (GEOBACK_TIME_LIMIT; the worker sets it as the commands do): a
# diagnosis of Mohr-Coulomb ground takes minutes even on these meshes; past the limit it stops with what
# it found, and work that cannot stop early is cut at the limit plus its grace (budget.MIN_GRACE), well
# within HANG_SECONDS
TIME_LIMIT = 20.0

# raw Python / numpy wording that must never reach a user
RAW = re.compile(r"Traceback|\b(Value|Type|Key|Index|Attribute|ZeroDivision|Runtime|LinAlg|Assertion|Overflow|"
                 r"FloatingPoint|Recursion|Memory|NotImplemented|Name|UnboundLocal)Error\b|division by zero|"
                 r"could not convert|has no attribute|NoneType|not subscriptable|unsupported operand|"
                 r"index \d+ is out of bounds|list index out of range|could not be broadcast|Singular matrix|"
                 r"must not contain infs or NaNs|math domain error|invalid value encountered|overflow encountered|"
                 r"divide by zero encountered|Input should|Value error|<class '|dtype\(|numpy\.|object of type|"
                 r"takes \d+ positional|got an unexpected keyword|is not iterable|not supported between")


def base_data(kind: str) -> dict:
    data = yaml.safe_load((CASES / BASES[kind][0]).read_text(encoding="utf-8"))
    g = data["geometry"]
    data["mesh"] = dict(data.get("mesh") or {}, size_tunnel=COARSE["size_tunnel"] * g["radius"],
                        size_far=COARSE["far"] * max(g["width"], g["depth"]))
    data.setdefault("fit", {})["max_iterations"] = 6
    data["fit"]["mesh_error"] = "ignore"
    data.get("output", {}).pop("dir", None)
    return data


BASE_DATA = {k: base_data(k) for k in BASES}
READINGS = {name: (CASES / name).read_text(encoding="utf-8") for _, files in BASES.values() for name in files}


# ------------------------------------------------------------------------------------- mutations
FACTORS = [0.0, 1e-9, 1e-6, 1e-3, 0.1, 0.5, 0.9, 0.99, 1.01, 1.1, 2.0, 10.0, 1e3, 1e6, -1.0, -0.5]
SPECIAL = [0, 1, -1, 1e-12, 1e-6, 0.5, 0.999999, 1.000001, 1e6, 1e12, 1e300, float("nan"), float("inf"),
           float("-inf"), "1e-3 MPa", "10 MPa", "5 GPa", "-0"]
RELEASES = [1e-9, 1e-6, 1e-3, 0.05, 0.3, 0.5, 0.7, 0.9, 0.999999, 1.0, 1.2]
NAMES = {"elastic": ["E", "K0", "nu", "E[clay]", "nu[clay]", "K0[clay]", "A[SM1]", "B[I1]", "bias[I1]", "zoff[I1]",
                     "Egrad[clay]", "beta", "n[clay]"],
         "scales": ["E", "K0", "nu", "A[SM1]", "B[I1]", "bias[I1]"],
         "staged": ["E", "K0", "nu", "beta[advance]", "E[shotcrete]", "nu[shotcrete]", "A[X1.advance]", "B[I1]"],
         "forecast": ["E", "K0", "beta[advance]", "E[shotcrete]", "A[X1.advance]", "bias[I1]"],
         "plastic": ["E", "K0", "nu", "c", "phi", "psi", "tension", "c[marl]", "phi[marl]", "psi[marl]",
                     "beta[face-near]", "beta[final]", "A[X1]", "B[I1]"]}


FIT_VALUES = {"method": ["gn", "lm", "lm-scaled"], "weighting": ["full", "diagonal", "identity"],
              "max_iterations": [1, 2, 3, 6], "mesh_error": ["check", "include", "ignore"], "mu0": [1e-3, 1.0, 1e3],
              "step_tol": [1e-12, 1e-3, 0.5], "objective_tol": [1e-14, 1e-2, 0.9]}
# what a mutation changes: mostly what a valid case may say (the validate fuzzer covers broken files)
MUTATIONS = ["scale", "scale", "special", "drop", "duplicate", "stages", "stages", "strength", "strength",
             "parameter", "parameter", "readings", "csv", "csv", "forecast", "forecast", "scales", "scales",
             "fit", "fit", "mesh", "swap"]


# strength values: (usual, odd)
STRENGTH = {"c": ([5, 20, 50, 200, 1e4], [0, 1e-3, 1e9, -5]), "phi": ([15, 25, 30, 40, 44.9], [0, 0.1, 60, 89.9, 90]),
            "psi": ([0, 5, 10, 20], [30, 45, -5, 89]), "tension": ([0, 1, 10], [100, -1])}
# a parameter's usual size, by its stem
TYPICAL = {"E": 3e4, "K0": 0.8, "nu": 0.3, "c": 50.0, "phi": 30.0, "psi": 5.0, "tension": 5.0, "beta": 0.5,
           "A": 1e-3, "B": 1e-3, "bias": 1e-4, "zoff": 0.1, "Egrad": 100.0, "n": 1.5}


def _pick(rnd, usual: list, odd: list):
    """A usual value three times in four, else an odd one."""
    return rnd.choice(usual if rnd.random() < 0.75 else odd)


def _numbers(data):
    return [p for p, v in _paths(data) if isinstance(v, (int, float)) and not isinstance(v, bool)]


def _mutate_once(kind: str, data: dict, files: dict, rnd) -> None:
    """One mutation of the case data (and of its readings files, `files`: name -> text) in place."""
    what = rnd.choice(MUTATIONS)
    if what == "scale":
        numbers = _numbers(data)
        if numbers:
            at = rnd.choice(numbers)
            _get(data, at[:-1])[at[-1]] = _get(data, at) * _pick(rnd, [0.5, 0.9, 1.1, 2.0], FACTORS)
    elif what == "special":
        numbers = _numbers(data)
        if numbers:
            at = rnd.choice(numbers)
            _get(data, at[:-1])[at[-1]] = rnd.choice(SPECIAL)
    elif what == "drop":
        paths = [p for p, _ in _paths(data) if p[0] not in ("name",)]
        if paths:
            at = rnd.choice(paths)
            del _get(data, at[:-1])[at[-1]]
    elif what == "duplicate":
        lists = [p for p, v in _paths(data) if isinstance(v, list) and v]
        if lists:
            at = rnd.choice(lists)
            seq = _get(data, at)
            seq.insert(rnd.randrange(len(seq) + 1), copy.deepcopy(rnd.choice(seq)))
    elif what == "stages":
        c = data.setdefault("construction", {"stages": [{"name": "s1", "release": 1.0}]})
        stages = c.get("stages") if isinstance(c, dict) else None
        if isinstance(stages, list):
            for s in stages:
                if isinstance(s, dict) and (rnd.random() < 0.5):
                    s["release"] = rnd.choice(RELEASES)
            if (rnd.random() < 0.5) and stages and isinstance(stages[0], dict):
                stages.insert(0, {"name": "tiny", "release": rnd.choice([1e-9, 1e-6, 1e-4, 1e-2])})
    elif what == "strength":
        layers = data.get("ground", {}).get("layers")
        if isinstance(layers, list) and layers and isinstance(layers[0], dict):
            layer = rnd.choice(layers)
            layer["model"] = "mohr-coulomb"
            for field, (usual, odd) in STRENGTH.items():
                if rnd.random() < 0.5:
                    layer[field] = _pick(rnd, usual, odd)
            if isinstance(layer.get("phi"), (int, float)) and isinstance(layer.get("psi"), (int, float)) \
                    and rnd.random() < 0.75:
                layer["psi"] = min(layer["psi"], layer["phi"])
    elif what == "parameter":
        params = data.setdefault("parameters", [])
        if isinstance(params, list):
            name = rnd.choice(NAMES[kind])
            typical = TYPICAL.get(name.split("[")[0], 1.0)
            spec = {"name": name, "initial": _pick(rnd, [typical * f for f in (0.3, 0.7, 1.0, 1.5, 3.0)],
                                                   [0, 1e-6, -1, 1e9])}
            if rnd.random() < 0.5:
                spec["bounds"] = _pick(rnd, [[typical / 10, typical * 10], [typical / 2, typical * 2]],
                                       [sorted(rnd.choices([-1, 0, 1e-3, 0.5, 1, 10, 45, 1e5, 1e9], k=2),
                                               reverse=rnd.random() < 0.5)])
            if rnd.randint(0, 3) == 0:
                spec["prior"] = _pick(rnd, [{"mean": typical, "std": typical / 4}],
                                      [{"mean": rnd.choice([0, 1, 1e4]), "std": rnd.choice([0, 1e-9, 1, 1e9])}])
            if params and rnd.random() < 0.5:
                params[rnd.randrange(len(params))] = spec
            else:
                params.append(spec)
    elif what == "readings":
        lists = [(p, v) for p, v in _paths(data) if p and p[-1] == "readings" and isinstance(v, list)]
        if lists:
            at, values = rnd.choice(lists)
            how = rnd.choice(["zero", "constant", "scale", "reverse", "shorten", "nan", "huge"])
            if how == "zero":
                new = [0.0] * len(values)
            elif how == "constant":
                new = [1e-3] * len(values)
            elif how == "scale":
                f = rnd.choice(FACTORS)
                new = [v * f if isinstance(v, (int, float)) else v for v in values]
            elif how == "reverse":
                new = list(reversed(values))
            elif how == "shorten":
                new = values[:max(0, len(values) - 1)]
            elif how == "nan":
                new = list(values)
                if new:
                    new[rnd.randrange(len(new))] = float("nan")
            else:
                new = [v * 1e12 if isinstance(v, (int, float)) else v for v in values]
            _get(data, at[:-1])[at[-1]] = new
    elif what == "csv" and files:
        name = rnd.choice(sorted(files))
        lines = files[name].split("\n")
        how = rnd.choice(["stage", "drop", "duplicate", "header", "value", "blank_stage"])
        body = [i for i, line in enumerate(lines) if i > 0 and line.strip()]
        if body:
            i = rnd.choice(body)
            cells = lines[i].split(",")
            if how == "stage" and len(cells) >= 4:
                cells[1] = rnd.choice(["advance", "lined", "final", "face-near", "face-past", "nope", "",
                                                 "ADVANCE", " advance"])
                lines[i] = ",".join(cells)
            elif how == "blank_stage" and len(cells) >= 4:
                for j in body:
                    c = lines[j].split(",")
                    c[1] = ""
                    lines[j] = ",".join(c)
            elif how == "drop":
                del lines[i]
            elif how == "duplicate":
                lines.insert(i, lines[i])
            elif how == "header":
                lines[0] = rnd.choice(["instrument,station,reading [mm]", "instrument,stage,station,reading",
                                                 "instrument,stage,station,reading [m]", "stage,instrument,station,reading [mm]"])
            elif how == "value":
                cells[-1] = rnd.choice(["0", "1e9", "-1e9", "nan", "inf", "1e-300", "x"])
                lines[i] = ",".join(cells)
        files[name] = "\n".join(lines)
    elif what == "forecast":
        fcs = data.setdefault("forecasts", [])
        if isinstance(fcs, list):
            stages = [st_.get("name") for st_ in (data.get("construction") or {}).get("stages", [])
                      if isinstance(st_, dict)] if isinstance(data.get("construction"), dict) else []
            stage = rnd.choice([None, None, "nope"] + stages * 3)
            g = data.get("geometry", {})
            w = g.get("width", 50) if isinstance(g, dict) else 50
            choice = rnd.choice(["points", "line", "convergence", "instrument", "lining"])
            if choice == "points":
                fc = {"name": "Fp", "kind": "points", "points": [[rnd.choice([0.0, 1.0, w, w * 2, -1.0]),
                                                                  rnd.choice([0.0, -5.0, -15.0, 1.0, -1e4])]],
                      "components": rnd.choice([["uy"], ["ux", "uy"], ["ux"]])}
            elif choice == "line":
                fc = {"name": "Fl", "kind": "line", "start": [0.0, 0.0], "end": [rnd.choice([0.0, 10.0, w, 2 * w]), 0.0],
                      "points": rnd.choice([0, 1, 2, 5, 31, 10 ** 5])}
            elif choice == "convergence":
                fc = {"name": "Fc", "kind": "convergence", "points": rnd.choice(
                    [[[0.0, -12.0], [3.0, -15.0]], [[0.0, -12.0], [0.0, -12.0]], [[0.0, -15.0], [3.0, -15.0]]])}
            elif choice == "instrument":
                names = [i.get("name") for i in data.get("instruments", []) if isinstance(i, dict)] or ["X"]
                fc = {"name": "Fi", "kind": "instrument", "instrument": rnd.choice(names + ["nope"])}
            else:
                fc = {"name": "Fn", "kind": "lining", "quantities": rnd.choice([["N"], ["N", "M", "V"]])}
            if stage is not None:
                fc["stage"] = stage
            if (rnd.random() < 0.5):
                fc["alert"] = rnd.choice([0.0, 1e-6, 0.006, -0.01, 1e9])
            fcs.append(fc)
    elif what == "scales":
        names = [i.get("name") for i in data.get("instruments", []) if isinstance(i, dict)] or ["X"]
        group = {"instruments": rnd.choices(names + ["nope"], k=rnd.randint(1, 3)),
                 "scale": rnd.choice(["estimate", "known"])}
        if group["scale"] == "estimate" and (rnd.random() < 0.5):
            group["prior"] = rnd.choice([{"within": 2}, {"within": 1.0001}, {"within": 1e6},
                                                   {"within": 3, "shape": "inverse-chi2"}, {"within": 0.5}])
        scales = data.setdefault("error_scales", [])
        if isinstance(scales, list):
            scales.append(group)
    elif what == "fit":
        fit = data.setdefault("fit", {})
        if isinstance(fit, dict):
            key = rnd.choice(list(FIT_VALUES))
            fit[key] = rnd.choice(FIT_VALUES[key] if rnd.random() < 0.8 else ["gn", "full", 1, 0.0, 1e9, "x"])
    elif what == "mesh":
        mesh = data.setdefault("mesh", {})
        g = data.get("geometry", {})
        radius = g.get("radius", 3.0) if isinstance(g, dict) and isinstance(g.get("radius"), (int, float)) else 3.0
        if isinstance(mesh, dict):
            field = rnd.choice(["size_tunnel", "size_far", "size_instruments", "growth", "order"])
            if field == "order":
                mesh[field] = rnd.choice([1, 2])
            elif field == "growth":
                mesh[field] = rnd.choice([0.02, 0.2, 1.0, 2.0])
            else:
                mesh[field] = radius * rnd.choice([FINEST, 0.4, 0.8, 2.0, 10.0])
    elif what == "swap":
        lists = [p for p, v in _paths(data) if isinstance(v, list) and len(v) > 1]
        if lists:
            seq = _get(data, rnd.choice(lists))
            i, j = rnd.randrange(len(seq)), rnd.randrange(len(seq))
            seq[i], seq[j] = seq[j], seq[i]


def _keep_small(data: dict) -> None:
    """Mesh sizes above the floor (FINEST of the radius, a far size of at least twice that)."""
    g, mesh = data.get("geometry"), data.get("mesh")
    if not isinstance(g, dict) or not isinstance(mesh, dict):
        return
    r = g.get("radius")
    if not isinstance(r, (int, float)) or not math.isfinite(r) or r <= 0:
        return
    for field, least in (("size_tunnel", FINEST * r), ("size_far", 2 * FINEST * r), ("size_instruments", FINEST * r)):
        v = mesh.get(field)
        if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and 0 < v < least:
            mesh[field] = least
    if isinstance(mesh.get("growth"), (int, float)) and 0 < mesh["growth"] < 0.1:
        mesh["growth"] = 0.1  # slow growth from small sizes: many elements


@st.composite
def mutant(draw, kinds=tuple(BASES)):
    """(kind, case data, readings files by name, the API steps to take)."""
    rnd = random.Random(draw(st.integers(0, 2 ** 32 - 1)))  # uniform choices (hypothesis' draws favour their ends)
    kind = rnd.choice(kinds)
    data = copy.deepcopy(BASE_DATA[kind])
    files = {name: READINGS[name] for name in BASES[kind][1]}
    for _ in range(rnd.choice([1, 1, 1, 2, 2, 3])):
        _mutate_once(kind, data, files, rnd)
    _keep_small(data)
    steps = ["validate"]
    level = rnd.random()
    if level < 0.5:
        steps += ["identify", "forecast"]
    if level < 0.03:
        steps += ["diagnose"]
    elif level < 0.08:
        steps += ["run_case"]
    return kind, data, files, steps


# ------------------------------------------------------------------------------------- the worker
_WORKER = r"""
import json, os, sys, traceback, warnings
sys.argv[0] = 'geoback'
import geoback
from geoback.errors import GeobackError
from geoback.commands.validation import check_case

def outcome(steps, case, out):
    done, loaded, analysis, res = [], None, None, None
    for step in steps:
        if step == 'validate':
            loaded = geoback.load_case(case)
            check_case(loaded)
        elif step == 'identify':
            analysis = geoback.prepare(loaded)
            if analysis.misfit is None or analysis.misfit.n == 0:
                done.append('identify: nothing to identify')
                break
            res = geoback.identify(analysis, profile='auto', mesh_error=None)
        elif step == 'forecast':
            if loaded.case.forecasts and res is not None:
                try:  # a fit that never moved has no estimate: refused in words (the rest goes on)
                    geoback.forecast(analysis, res)
                except GeobackError as exc:
                    if res.fit.moved or not str(exc).startswith('forecast: the identification stopped without moving'):
                        raise
        elif step == 'diagnose':
            geoback.diagnose(loaded, max_rounds=1, refit_top=2)
        elif step == 'run_case':
            geoback.run_case(loaded, out)
        done.append(step)
    return done

from geoback.case import budget

for line in sys.stdin:
    req = json.loads(line)
    out = {'done': [], 'error': None, 'traceback': None, 'warnings': []}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        try:
            with budget.limited(budget.default_seconds()):  # as the commands do
                out['done'] = outcome(req['steps'], req['case'], req['out'])
                out['time_limit'] = budget.reached()
        except GeobackError as exc:
            out['error'] = str(exc)
            out['error_type'] = type(exc).__name__
        except BaseException:
            out['traceback'] = traceback.format_exc()
    out['warnings'] = [f'{w.category.__name__}: {w.message} ({w.filename}:{w.lineno})' for w in caught]
    print(json.dumps(out), flush=True)
"""


class ApiWorker:
    """A long-lived interpreter running API steps on one case per request, in `cwd`."""

    def __init__(self, env: dict, cwd: Path):
        self.env, self.cwd = env, cwd
        self.proc = None

    def _start(self):
        self.errors = tempfile.TemporaryFile(mode="w+")
        self.proc = subprocess.Popen([sys.executable, "-c", _WORKER], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=self.errors, text=True, env=self.env, cwd=self.cwd)

    def run(self, case: Path, steps: list, out: Path, timeout: float = HANG_SECONDS) -> dict:
        if self.proc is None or self.proc.poll() is not None:
            self._start()
        self.errors.seek(0, os.SEEK_END)
        mark = self.errors.tell()
        t0 = time.perf_counter()
        self.proc.stdin.write(json.dumps({"case": str(case), "steps": steps, "out": str(out)}) + "\n")
        self.proc.stdin.flush()
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout)
        if not ready:
            self.close(kill=True)
            return {"hung": True, "seconds": time.perf_counter() - t0}
        line = self.proc.stdout.readline()
        seconds = time.perf_counter() - t0
        self.errors.seek(mark)
        stderr = self.errors.read()
        if not line:
            self.proc = None
            return {"died": stderr[-3000:], "seconds": seconds}
        out = json.loads(line)
        out["stderr"], out["seconds"] = stderr, seconds
        return out

    def close(self, kill: bool = False) -> None:
        if self.proc is None:
            return
        if kill:
            self.proc.kill()
        elif self.proc.poll() is None:
            self.proc.stdin.close()
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        self.proc.wait()
        self.proc = None
        self.errors.close()


def snapshot(folder: Path, skip: set) -> tuple:
    """The folder's identity and every file's size and modification time (names in `skip` aside)."""
    st_ = folder.stat()
    files = {}
    for path in sorted(folder.rglob("*")):
        rel = path.relative_to(folder)
        if rel.parts and rel.parts[0] in skip:
            continue
        s = path.lstat()
        files[str(rel)] = (s.st_size, s.st_mtime_ns, path.is_dir())
    return (st_.st_dev, st_.st_ino), files


def check_text(text: str, where: str) -> None:
    found = RAW.search(text)
    assert not found, f"raw Python/numpy wording ({found.group(0)!r}) {where}: {text[-2000:]}"


class ApiFuzz:
    """Writes each mutant into a working folder, runs it through the worker (and a sample through the
    command line), and checks the answer and the folders."""

    def __init__(self, folder: Path, cli_every: int = 0):
        self.folder = folder
        self.work = folder / "work"
        self.work.mkdir()
        self.out = self.work / "out"  # the only place results may go (API: out/api, commands: out/<command>)
        self.env = dict(os.environ, GEOBACK_CACHE=str(folder / "cache"), OPENBLAS_NUM_THREADS="1",
                        MKL_NUM_THREADS="1", OMP_NUM_THREADS="1")
        for var in ("GEOBACK_DEBUG", "GEOBACK_MAX_DOFS"):
            self.env.pop(var, None)
        self.env["GEOBACK_TIME_LIMIT"] = str(TIME_LIMIT)
        self.worker = ApiWorker(self.env, self.work)
        self.cli_every = cli_every
        self.count = 0
        self.stats = {"examples": 0, "by_kind": {}, "steps": {}, "refused": 0, "cli": 0, "max_seconds": 0.0,
                      "errors": {}, "seconds": {}, "time_limited": 0, "refused_at": {}}
        self.cases_before = snapshot(CASES, set())

    def check(self, example) -> None:
        kind, data, files, steps = example
        self.count += 1
        self.stats["examples"] += 1
        self.stats["by_kind"][kind] = self.stats["by_kind"].get(kind, 0) + 1
        for name in BASES[kind][1]:
            (self.work / name).write_text(files.get(name, READINGS[name]), encoding="utf-8")
        case = self.work / "case.yaml"
        case.write_text(yaml.safe_dump(data, sort_keys=False, allow_unicode=True), encoding="utf-8")
        text = case.read_text(encoding="utf-8")
        before = snapshot(self.work, {"out"})
        res = self.worker.run(case, steps, self.out / "api")
        assert not res.get("hung"), f"hung for {res['seconds']:.0f} s in {steps}:\n{text}"
        assert "died" not in res, f"the worker died in {steps}: {res['died']}\n{text}"
        assert res["traceback"] is None, f"{res['traceback']}\n{text}"
        self.stats["max_seconds"] = max(self.stats["max_seconds"], res["seconds"])
        key = f"{kind}:{steps[-1]}"
        self.stats["seconds"][key] = round(self.stats["seconds"].get(key, 0.0) + res["seconds"], 1)
        if res.get("time_limit"):
            self.stats["time_limited"] += 1
        for step in res["done"]:
            self.stats["steps"][step] = self.stats["steps"].get(step, 0) + 1
        if res["error"] is not None:
            self.stats["refused"] += 1
            message = res["error"]
            key = res.get("error_type", "?")
            self.stats["errors"][key] = self.stats["errors"].get(key, 0) + 1
            field = re.match(r"^[^:]+:\d+:\d+: ([^:]+):", message)
            where = field.group(1).split(".")[0].split("[")[0] if field else message[:30]
            self.stats["refused_at"][where] = self.stats["refused_at"].get(where, 0) + 1
            assert message.strip(), f"an empty message:\n{text}"
            check_text(message, f"in the message of {steps}")
        assert not res["warnings"], f"Python warnings {res['warnings']} in {steps}:\n{text}"
        check_text(res["stderr"], f"on stderr of {steps}")
        after = snapshot(self.work, {"out"})
        assert after == before, f"the working folder changed outside out/: {_diff(before, after)}\n{text}"
        if self.cli_every and self.count % self.cli_every == 0:
            self.cli(case, text, "diagnose" if "diagnose" in steps else "run")

    def cli(self, case: Path, text: str, command: str) -> None:
        before = snapshot(self.work, {"out"})
        args = [command, case, "-q", "--out", self.out / command] + (["--no-plots"] if command == "diagnose" else [])
        run = run_cli(args, self.folder, env=self.env, cwd=self.work, timeout=HANG_SECONDS)
        self.stats["cli"] += 1
        everything = run.stdout + run.stderr
        check_text(everything, f"from geoback {command}")
        assert run.returncode in (0, 1, 2, 3), (run.returncode, everything, text)
        for line in run.stderr.splitlines():
            assert not line.strip() or line.startswith(("error: ", "notice: ", "warning: ", "  ", "-> ")), \
                f"stray stderr line {line!r} from geoback {command}:\n{text}"
        assert snapshot(self.work, {"out"}) == before, f"geoback {command} touched the working folder:\n{text}"

    def close(self) -> None:
        self.worker.close()
        assert snapshot(CASES, set()) == self.cases_before, "the shipped cases changed"
        shutil.rmtree(self.out, ignore_errors=True)


def _diff(before, after) -> str:
    if before[0] != after[0]:
        return f"identity {before[0]} -> {after[0]}"
    a, b = before[1], after[1]
    return ", ".join(f"{k}: {a.get(k)} -> {b.get(k)}" for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k))
