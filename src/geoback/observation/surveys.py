"""Surveys of an instrument in a readings file: its rows grouped in surveys (a date or survey column),
each placed in a construction stage (the stage column, the case's stage:, or the stage in force on
its date: ``case.dates``), the baseline (zero) survey found and checked against every other, and the
reading sets that result (``SetInfo``: one a stage, or one a survey; ``Sets``: with the stage after
which the instrument reads increments). ``readings.file_readings`` reads the values of each set.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geoback.case.dates import BEFORE, parse_date, shown_date, stage_on

BASELINE_WORDS = {"baseline", "base", "zero", "initial", "base reading", "nullmessung", "initial reading"}
BEFORE_WORDS = {"", "-", "before", "initial", "baseline", "none", "pre-construction"}


@dataclass(frozen=True)
class SetInfo:
    """One set of readings of an instrument: the stage it was read at, the survey (its date or name;
    None: the file does not tell surveys apart), how many surveys it averages, and its key in
    ``CaseReadings.values`` (the stage, or 'stage@survey')."""

    name: str
    stage: str
    survey: str | None = None
    when: object = None  # datetime of the survey (None: undated)
    count: int = 1
    key: tuple = ()  # its rows in _Surveys.rows

    @property
    def label(self) -> str:
        return f"stage {self.stage}" + (f", survey {self.survey}" if self.survey else "")


@dataclass(frozen=True)
class Sets:
    """An instrument's reading sets (name -> SetInfo) and the stage after which it reads increments
    (None: since before construction)."""

    sets: dict
    since: str | None = None


@dataclass
class _Baseline:
    key: tuple
    survey: str
    stage: str | None
    when: object
    lines: str

    @property
    def label(self) -> str:
        return f"the baseline survey {self.survey}"


class Surveys:
    """The rows of one instrument grouped in surveys and placed in stages (``case.dates`` rule), the
    baseline survey found, and every date and stage checked against it."""

    def __init__(self, table, block, ins, stages, periods, roles, fail, err):
        self.table, self.block, self.ins, self.stages, self.periods = table, block, ins, stages, periods
        self.roles, self.fail, self.err = roles, fail, err
        self.dated = "date" in roles or "survey" in roles
        self.rows: dict[tuple, list] = {}
        self.info: dict[tuple, dict] = {}
        if "stage" in roles:
            if ins.stage is not None:
                raise err(("stage",), f"expected either a stage column in {table.path.name} or stage: in the case, "
                                      f"found both")
            self.staged_by = "stage column"
        elif ins.stage is not None:
            self.staged_by = f"stage: {ins.stage} in the case"
        elif "date" in roles and periods is not None:
            self.staged_by = "placed by date: the stage in force on each"
        elif len(stages) == 1:
            self.staged_by = "the case's only stage"
        elif "date" in roles:
            raise fail(f"{table.path.name} has survey dates but the construction stages ({', '.join(stages)}) have "
                       f"none: expected a date on every stage (date: 2026-03-05, or [start, end]) to place the "
                       f"surveys, or a stage column")
        else:
            raise fail(f"{table.path.name} has no stage column and the case has construction stages "
                       f"{', '.join(stages)}: expected a stage column, a date column with dated stages, or the stage "
                       f"the readings of '{block.name}' were taken at (stage: {stages[-1]}, say)")

    def _is_baseline(self, when, label) -> bool:
        said = self.ins.baseline
        if label is not None and label.strip().lower() in BASELINE_WORDS:
            if said is not None and said != label and not (when is not None and not isinstance(said, str)
                                                           and _same_day(said, when)):
                raise self.fail(f"two baselines for '{self.block.name}': baseline: {_said(said)} in the case and the "
                                f"survey '{label}' in {self.table.path.name}: expected one")
            return True
        if said is None:
            return False
        if isinstance(said, str):
            return label == said
        return when is not None and _same_day(said, when)

    def add(self, line: int, fields: list[str]) -> None:
        roles, fail, where = self.roles, self.fail, self.table.where(line)
        when = label = None
        if "date" in roles:
            try:
                when = parse_date(fields[roles["date"]])
            except ValueError as exc:
                raise fail(f"{where}: {exc}") from None
        if "survey" in roles:
            label = fields[roles["survey"]].strip()
            if not label:
                raise fail(f"{where}: expected the survey's name or number in the survey column, found an empty cell")
        base = self._is_baseline(when, label)
        survey = label if label is not None else (shown_date(when) if when is not None else None)
        if "stage" in roles:
            text = fields[roles["stage"]].strip()
            if base and text.lower() in BEFORE_WORDS:
                stage = BEFORE
            elif text not in self.stages:
                raise fail(f"{where}: stage '{text}' is not a construction stage of the case "
                           f"(stages: {', '.join(self.stages)})")
            else:
                stage = text
            if self.periods is not None and when is not None:
                try:
                    on = stage_on(self.periods, when)
                except ValueError as exc:
                    raise fail(f"{where}: the survey of '{self.block.name}' dated {exc}") from None
                if on != stage and not (base and stage is BEFORE):
                    raise fail(f"{where}: expected stage '{on or 'before construction'}' for a survey dated "
                               f"{shown_date(when)} (the stage in force then), found stage '{text}'")
        elif self.ins.stage is not None:
            stage = self.ins.stage
        elif "date" in roles and self.periods is not None:
            try:
                stage = stage_on(self.periods, when)
            except ValueError as exc:
                raise fail(f"{where}: the survey of '{self.block.name}' dated {exc}") from None
            if stage is BEFORE and not base:
                first = self.periods[0]
                raise fail(f"{where}: a survey of '{self.block.name}' dated {shown_date(when)}, before construction "
                           f"began (stage '{first[0]}' on {shown_date(first[1])}): expected it on or after that date; "
                           f"only the baseline survey may come before (baseline: {shown_date(when)} in the case, if "
                           f"it is the zero reading)")
        else:
            stage = self.stages[0]
        key = (base, survey, stage)
        if key not in self.rows:
            same = [k for k in self.rows if k[1] == survey and survey is not None and k[0] == base]
            if same:
                raise fail(f"{where}: survey {survey} of '{self.block.name}' is placed in stage '{stage}' here and in "
                           f"stage '{same[0][2]}' on line {self.info[same[0]]['lines'][0]}: expected one stage a survey")
            self.rows[key], self.info[key] = [], {"when": when, "lines": []}
        self.rows[key].append((line, fields))
        self.info[key]["lines"].append(line)

    def finish(self) -> list[SetInfo]:
        """The reading sets in construction order (then by date), the baseline kept apart; every
        survey checked to come after the baseline and at or after the installation."""
        fail, name, stages = self.fail, self.block.name, self.stages
        bases = [k for k in self.rows if k[0]]
        if len(bases) > 1:
            a, b = bases[:2]
            raise fail(f"{self.table.where(self.info[b]['lines'][0])}: two baselines for '{name}': surveys {a[1]} "
                       f"and {b[1]}: expected one")
        said = self.ins.baseline
        if said is not None and not bases:
            found = sorted({k[1] for k in self.rows if k[1] is not None})
            raise fail(f"{self.table.where()}: expected the baseline survey {_said(said)} of '{name}', found "
                       f"{'surveys ' + ', '.join(found[:8]) if found else 'no date or survey column'}")
        self.baseline = None
        self.since = self.ins.installed_after
        if bases:
            k = bases[0]
            lines = self.info[k]["lines"]
            self.baseline = _Baseline(k, k[1] or "(baseline)", k[2], self.info[k]["when"], f"{min(lines)}-{max(lines)}")
            if self.since is not None and self.since != k[2]:
                raise self.err(("installed_after",), f"expected installed_after to agree with the baseline "
                                                          f"survey's stage ('{k[2] or 'before construction'}'), found "
                                                          f"'{self.since}'")
            self.since = k[2]
        sets = []
        order = {s: j for j, s in enumerate(stages)}
        for key in sorted((k for k in self.rows if not k[0]),
                          key=lambda k: (order[k[2]], self.info[k]["when"] or 0, self.info[k]["lines"][0])):
            _, survey, stage = key
            when = self.info[key]["when"]
            line = self.info[key]["lines"][0]
            if self.baseline is not None and self.baseline.when is not None and when is not None \
                    and when < self.baseline.when:
                raise fail(f"{self.table.where(line)}: survey {survey} of '{name}' is dated before its baseline survey "
                           f"({shown_date(self.baseline.when)}): expected every survey on or after the baseline")
            if self.since is not None and order[stage] < order[self.since]:
                raise fail(f"{self.table.where(line)}: '{name}' was read at stage '{stage}', before it was installed "
                           f"(after stage '{self.since}'): expected readings at stage '{self.since}' or later")
            set_name = stage if survey is None else f"{stage}@{survey}"
            sets.append(SetInfo(set_name, stage, survey, when, 1, key))
        return sets

def _same_day(said, when) -> bool:
    """A baseline given as a day matches any time on it; a date-time matches exactly."""
    if said.hour == said.minute == said.second == 0:
        return said.date() == when.date()
    return said == when


def _said(said) -> str:
    return said if isinstance(said, str) else shown_date(said)


def averaged(out: dict, meta: dict, block, fail, table) -> tuple[dict, dict]:
    """`surveys: average`: the sets of each stage replaced by their mean (C_x / n where n surveys)."""
    by_stage: dict[str, list[str]] = {}
    for name, m in meta.items():
        by_stage.setdefault(m.stage, []).append(name)
    new, info = {}, {}
    for stage, names in by_stage.items():
        stack = np.array([out[n] for n in names])
        gone = np.isnan(stack)
        if gone.any() and not gone.all(axis=0)[gone.any(axis=0)].all():
            raise fail(f"{table.where()}: '{block.name}' at stage {stage}: a reading missing in some surveys only "
                       f"cannot be averaged with one C_x / n: expected the same readings in every survey of a stage "
                       f"(or surveys: separate)")
        new[stage] = stack.mean(axis=0)
        info[stage] = SetInfo(stage, stage, " + ".join(str(meta[n].survey) for n in names), meta[names[-1]].when,
                              len(names))
    return new, info
