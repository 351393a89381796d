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
from geoback.cli import app
app()
"""


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
