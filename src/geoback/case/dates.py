"""Time in a case: survey dates, stage dates, and the rule that places a survey in a stage.

Dates are read in the forms instrument software and spreadsheets export, without guessing: ISO
(2026-03-05, 2026-03-05 08:30, 2026-03-05T08:30:00) and the European day-first forms with dots
(05.03.2026, 05.03.2026 08:30). A slashed date (03/05/2026) is refused: it is 3 May in Europe and
5 March in the USA, and a survey placed in the wrong month is a silent wrong answer.

The rule (written in every report that uses it): a survey belongs to the stage *in force* on its
date, the last stage begun on or before it. A stage given as a range [start, end] is in force from
start to end inclusive; a date after its end and before the next stage's start lies in no stage and
is refused. A date before the first stage began is before construction: only an instrument's
baseline survey may be there (the ground before any excavation).
"""
from __future__ import annotations

import datetime as dt
import re

BEFORE = None  # the stage of a survey dated before construction began
RULE = ("each survey is placed in the stage in force on its date (the last stage begun on or before it; a stage "
        "given as a range ends on its end date); a baseline survey before the first stage reads the ground before "
        "construction")

_ISO = re.compile(r"^(\d{4})-(\d{1,2})-(\d{1,2})(?:[ T](\d{1,2}):(\d{2})(?::(\d{2})(?:\.\d+)?)?)?$")
_DOTS = re.compile(r"^(\d{1,2})\.(\d{1,2})\.(\d{4})(?:[ T](\d{1,2}):(\d{2})(?::(\d{2}))?)?$")
FORMS = "2026-03-05 or 05.03.2026 (with an optional time: 2026-03-05 08:30)"


def parse_date(value) -> dt.datetime:
    """A date or date-time from a case (YAML reads 2026-03-05 as a date) or a readings file's cell;
    ValueError saying what was expected when it is none of the forms above or not a calendar date."""
    if isinstance(value, dt.datetime):
        return value
    if isinstance(value, dt.date):
        return dt.datetime(value.year, value.month, value.day)
    if not isinstance(value, str):
        raise ValueError(f"expected a date ({FORMS}), found {value!r}")
    text = value.strip()
    m = _ISO.match(text)
    if m:
        y, mo, d, h, mi, s = m.groups()
    else:
        m = _DOTS.match(text)
        if not m:
            hint = " (a slashed date is ambiguous: day and month cannot be told apart)" if "/" in text else ""
            raise ValueError(f"expected a date ({FORMS}), found '{text}'{hint}")
        d, mo, y, h, mi, s = m.groups()
    try:
        return dt.datetime(int(y), int(mo), int(d), int(h or 0), int(mi or 0), int(s or 0))
    except ValueError as exc:
        raise ValueError(f"expected a calendar date ({FORMS}), found '{text}' ({exc})") from None


def shown_date(when: dt.datetime) -> str:
    """ISO, without a time at midnight: '2026-03-05', '2026-03-05 08:30'."""
    if when.hour == when.minute == when.second == 0:
        return when.strftime("%Y-%m-%d")
    return when.strftime("%Y-%m-%d %H:%M" if when.second == 0 else "%Y-%m-%d %H:%M:%S")


def stage_periods(case) -> list[tuple[str, dt.datetime, dt.datetime | None]] | None:
    """(stage, start, end or None) of every stage in order when the case dates its stages, else None.
    The schema has checked that every stage has a date and that they increase."""
    con = case.construction
    if con is None or not con.stages or con.stages[0].date is None:
        return None
    out = []
    for s in con.stages:
        start, end = (s.date if isinstance(s.date, tuple) else (s.date, None))
        out.append((s.name, parse_date(start), None if end is None else parse_date(end)))
    return out


def stage_on(periods, when: dt.datetime) -> str | None:
    """The stage in force at `when` (module rule): BEFORE when construction had not begun; ValueError
    naming the stages around it when the date lies in no stage."""
    if when < periods[0][1]:
        return BEFORE
    current = None
    for name, start, end in periods:
        if start <= when:
            current = (name, start, end)
    name, start, end = current
    if end is not None and when > end + dt.timedelta(days=1) - dt.timedelta(microseconds=1):
        later = [p for p in periods if p[1] > when]
        after = f" and before stage '{later[0][0]}' began ({shown_date(later[0][1])})" if later else ""
        raise ValueError(f"{shown_date(when)} lies in no construction stage: after stage '{name}' ended "
                         f"({shown_date(end)}){after}")
    return name
