"""What a command allows the work it starts: a wall-clock limit, and where progress lines go (with
the size limit of ``meshsize``, the limits of the work a case may ask for; in the case room, the
lowest, so that physics and inference read it).

A command (or a library caller) sets both for everything it calls, with a context manager::

    with budget.limited(600, say=print):      # 10 min; progress lines to print
        result = geoback.identify(loaded)

and the long loops below read them, without any argument passed through the layers between:

- ``say(text)``: one progress line (a plastic forward run longer than a few seconds says which stage,
  increment and Newton iteration it is at); nowhere when no one listens.
- ``expired()``: the limit has passed. Work that can stop with what it has found does so at its next
  step: the optimiser ends with its best accepted point (``estimate.fit``: status 'not converged',
  the reason says so), the discretisation-error check is skipped, a diagnosis' remaining refits stop
  after their first evaluation, so `diagnose` and `run` write what they found.
- ``check(where)``: raises :class:`~geoback.errors.TimeLimit` once the limit *and its grace*
  (``GRACE`` of the limit, at least ``MIN_GRACE``) have passed: work that cannot stop early with a
  result (a non-linear forward run, ``plasticity.solve``) ends there, its message saying where it
  was (``where()``: the run, stage, increment) and what the command was doing (the last line said).

The state is a context variable: nested calls see the innermost setting, threads and other
contexts their own. Without ``limited`` nothing is limited and nothing is said.
"""
from __future__ import annotations

import contextvars
import math
import os
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Callable

from geoback.errors import GeobackError, TimeLimit

DEFAULT_SECONDS = 3600.0  # the commands' default limit (--time-limit, GEOBACK_TIME_LIMIT)
clock = time.monotonic  # the clock every limit is read on (tests replace it with one that counts)
GRACE = 0.25  # fraction of the limit granted to finish what cannot stop early
MIN_GRACE = 30.0  # seconds of grace at least


@dataclass
class _Budget:
    seconds: float | None
    say: Callable[[str], None] | None
    start: float = field(default_factory=lambda: clock())
    doing: str = ""  # the last progress line: what the command was doing
    expired_at: str = ""  # what the work was doing when the limit passed (the first to notice says)

    @property
    def deadline(self) -> float:
        return math.inf if self.seconds is None else self.start + self.seconds

    @property
    def hard_deadline(self) -> float:
        if self.seconds is None:
            return math.inf
        return self.deadline + max(MIN_GRACE, GRACE * self.seconds)


_STATE: contextvars.ContextVar[_Budget | None] = contextvars.ContextVar("geoback_budget", default=None)


def parse_seconds(text, what: str = "--time-limit") -> float | None:
    """Seconds from a number, or '1.5 h', '90 min', '30 s'; 0, 'none' or 'off': no limit (None)."""
    if text is None:
        return None
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        value = float(text)
    else:
        raw = str(text).strip().lower().replace("_", "")
        if raw in ("none", "off", "no", "inf", "unlimited"):
            return None
        units = {"h": 3600.0, "hr": 3600.0, "hour": 3600.0, "hours": 3600.0, "min": 60.0, "m": 60.0,
                 "minutes": 60.0, "s": 1.0, "sec": 1.0, "seconds": 1.0, "": 1.0}
        number = raw.rstrip("abcdefghijklmnopqrstuvwxyz ")
        unit = raw[len(number):].strip()
        try:
            value = float(number) * units[unit]
        except (ValueError, KeyError):
            raise GeobackError(f"{what}: expected a time in seconds (e.g. 600, '90 min', '2 h') or 'none', found "
                               f"'{text}'") from None
    if not math.isfinite(value) and value > 0:
        return None
    if not value >= 0 or not math.isfinite(value):
        raise GeobackError(f"{what}: expected a time of 0 s or more (0 or 'none': no limit), found '{text}'")
    return value if value > 0 else None


def default_seconds() -> float | None:
    """The commands' default limit: GEOBACK_TIME_LIMIT if set, else DEFAULT_SECONDS."""
    text = os.environ.get("GEOBACK_TIME_LIMIT", "").strip()
    return parse_seconds(text, "GEOBACK_TIME_LIMIT") if text else DEFAULT_SECONDS


@contextmanager
def limited(seconds: float | None = None, say: Callable[[str], None] | None = None):
    """Limit the work done inside to `seconds` of wall-clock time (None: no limit) and send its
    progress lines to `say` (None: nowhere)."""
    if seconds is not None and not (isinstance(seconds, (int, float)) and seconds > 0 and math.isfinite(seconds)):
        raise GeobackError(f"time limit: expected a positive number of seconds, found {seconds!r}")
    token = _STATE.set(_Budget(None if seconds is None else float(seconds), say))
    try:
        yield _STATE.get()
    finally:
        _STATE.reset(token)


def say(text: str, remember: bool = True) -> None:
    """A progress line; `remember`: it says what the command is doing (for a time-limit message),
    not only where a computation is."""
    b = _STATE.get()
    if b is None:
        return
    if remember:
        b.doing = text.strip()
    if b.say is not None:
        b.say(text)


def elapsed() -> float:
    b = _STATE.get()
    return 0.0 if b is None else clock() - b.start


def limit() -> float | None:
    b = _STATE.get()
    return None if b is None else b.seconds


def expired(where: str = "") -> bool:
    """Has the limit passed? (`where`: what the caller was doing, remembered for the message.)"""
    b = _STATE.get()
    if b is None or clock() < b.deadline:
        return False
    if not b.expired_at:
        b.expired_at = (where or "the work") + (f", {b.doing}" if b.doing else "")
    return True


def reached() -> str:
    """'' if the limit has not been reached, else where (for the words of a result cut short)."""
    b = _STATE.get()
    if b is None or not expired():
        return ""
    return b.expired_at


def describe_limit() -> str:
    b = _STATE.get()
    return "no time limit" if b is None or b.seconds is None else f"the time limit of {_duration(b.seconds)}"


def check(where: Callable[[], str] | str = "") -> None:
    """Raise TimeLimit once the limit and its grace have passed (see the module docstring)."""
    b = _STATE.get()
    if b is None or clock() < b.hard_deadline:
        return
    text = where() if callable(where) else where
    doing = f" while {b.doing}" if b.doing else ""
    raise TimeLimit(f"stopped at {describe_limit()} (and {_duration(b.hard_deadline - b.deadline)} of grace to "
                    f"finish): {text or 'working'}{doing}; raise it with --time-limit (or GEOBACK_TIME_LIMIT), "
                    f"or make the case cheaper (a coarser mesh, fewer parameters)")


def _duration(seconds: float) -> str:
    if seconds >= 3600 and seconds % 360 == 0:
        return f"{seconds / 3600:g} h"
    if seconds >= 60 and seconds % 6 == 0:
        return f"{seconds / 60:g} min"
    return f"{seconds:.3g} s"
