"""Run the geoback CLI in a subprocess and measure its wall time and peak memory.

The peak is the child's own VmHWM (read from /proc/self/status as it exits), not getrusage's
ru_maxrss: a child forked from a large pytest process inherits the parent's high-water mark
across exec, which would charge the test process's memory to the command.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

_RUNNER = r"""
import atexit, json, sys
OUT = {out!r}
def _peak():
    try:
        with open('/proc/self/status') as fh:
            kb = next(int(line.split()[1]) for line in fh if line.startswith('VmHWM:'))
        with open(OUT, 'w') as out:
            json.dump({{'peak_bytes': kb * 1024}}, out)
    except (OSError, StopIteration, ValueError):
        pass
atexit.register(_peak)
sys.argv[0] = 'geoback'
from geoback.commands.cli import app
app()
"""


# A guard against hangs only. Tests assert no wall-clock time (the machine may be busy: time is
# measured in benchmarks/, e.g. benchmarks/command_times.py); they bound work by counts (bytes,
# factorisations, iterations) and catch a hang with this generous limit.
HANG_SECONDS = 120.0


@dataclass
class Measured:
    returncode: int
    stdout: str
    stderr: str
    seconds: float
    peak_bytes: float  # NaN where /proc is unavailable


def run_cli(args: list, tmp: Path, env: dict | None = None, cwd=None, timeout: float = 300) -> Measured:
    """`geoback *args` in a fresh interpreter; its wall time and peak resident memory."""
    out_file = Path(tmp) / f".peak-{os.getpid()}-{time.monotonic_ns()}.json"
    code = _RUNNER.format(out=str(out_file))
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", code] + [str(a) for a in args],
                          capture_output=True, text=True, env=env if env is not None else dict(os.environ),
                          cwd=cwd, timeout=timeout)
    seconds = time.perf_counter() - t0
    try:
        peak = float(json.loads(out_file.read_text())["peak_bytes"])
        out_file.unlink()
    except (OSError, ValueError, KeyError):
        peak = float("nan")
    return Measured(proc.returncode, proc.stdout, proc.stderr, seconds, peak)


_WORKER = r"""
import json, sys, time, traceback

def _hwm():
    try:
        with open('/proc/self/status') as fh:
            return next(int(l.split()[1]) for l in fh if l.startswith('VmHWM:')) * 1024
    except (OSError, StopIteration, ValueError):
        return float('nan')

def _reset_hwm():
    try:
        with open('/proc/self/clear_refs', 'w') as fh:
            fh.write('5')  # Linux: the peak resident size restarts from the current one
        return True
    except OSError:
        return False

from geoback.case.loading import load_case
from geoback.errors import CaseError, GeobackError
from geoback.commands.validation import check_case

for line in sys.stdin:
    path = line.rstrip('\n')
    reset = _reset_hwm()
    t0 = time.perf_counter()
    out = {'ok': False, 'messages': [], 'traceback': None}
    try:
        out['verdict'] = check_case(load_case(path))
        out['ok'] = True
    except CaseError as exc:
        out['messages'] = [str(p) for p in exc.problems]
        out['message'] = str(exc)
    except GeobackError as exc:
        out['messages'] = [str(exc)]
        out['message'] = str(exc)
    except BaseException:
        out['traceback'] = traceback.format_exc()
    out['seconds'] = time.perf_counter() - t0
    out['peak_bytes'] = _hwm()
    out['peak_is_per_example'] = reset
    print(json.dumps(out), flush=True)
"""


class ValidateWorker:
    """A long-lived interpreter that runs the library path of `geoback validate` (load_case, then
    validation.check_case) on one file per request and reports the outcome, the seconds it took
    and the process's peak resident memory during it (Linux: the peak is reset before each
    file through /proc/self/clear_refs; elsewhere it is the running maximum, an upper bound)."""

    def __init__(self, env: dict | None = None):
        self.errors = tempfile.TemporaryFile(mode="w+")  # (a pipe could fill up and block the worker)
        self.proc = subprocess.Popen([sys.executable, "-c", _WORKER], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=self.errors, text=True, env=env if env is not None else dict(os.environ))

    def validate(self, path) -> dict:
        self.proc.stdin.write(f"{path}\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            self.errors.seek(0)
            raise RuntimeError(f"validate worker died: {self.errors.read()[-3000:]}")
        return json.loads(line)

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.stdin.close()
            self.proc.wait(timeout=30)
        self.errors.close()
