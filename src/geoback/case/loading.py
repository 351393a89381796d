"""The case file: YAML -> validated pydantic models, with file:line:column on every error.

The schema is in ``case_schema``, the physical checks in ``case_checks`` and the readable
validation messages in ``case_messages``; this module loads a file and ties them together.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from geoback.case.checks import physical_problems
from geoback.case.messages import clean_loc, described_problems, more_problems
from geoback.case.schema import (Case, Convergence, Deflectometer, FitSettings, Geometry, Ground,  # noqa: F401 (re-exported)
                          Inclinometer, Instrument, Layer, MeshSettings, Output, Parameter, PointsInstrument,
                          Prior, SlidingMicrometer, shown)
from geoback.errors import CaseError
from geoback.case.yamlmarks import format_path, load_yaml_with_marks, locate


def case_from_data(data: Any, marks: dict | None = None, file: str | None = None,
                   allow_large: bool = False) -> Case:
    """Validate already-parsed data; raise CaseError located in the file, carrying every problem
    found (``CaseError.problems``). A mesh estimated beyond the default size limit is one of the
    problems unless `allow_large`."""
    marks = marks or {}
    if not isinstance(data, dict):
        line, col = marks.get((), (1, 1))
        raise CaseError(f"expected a mapping of case fields (name:, geometry:, ground:, ...), found {shown(data)}",
                        file=file, line=line, column=col, field=format_path(()))
    try:
        case = Case.model_validate(data)
    except ValidationError as exc:
        try:
            problems = described_problems(exc.errors(), data, marks)
        except Exception:  # pragma: no cover - the plain pydantic wording is better than a crash
            problems = [(clean_loc(tuple(err["loc"]), data), err["msg"].replace("Input should be", "expected"))
                        for err in exc.errors()]
        raise located_problems(problems, marks, file) from None
    problems = physical_problems(case, allow_large=allow_large)
    if problems:
        raise located_problems(problems, marks, file)
    return case


def located_problems(problems: list[tuple[tuple, str]], marks: dict, file: str | None) -> CaseError:
    """One CaseError for a list of (path, message): the first, '(and N more problems)', and all of
    them in ``.problems``."""
    located = []
    for at, message in problems:
        line, col = locate(at, marks)
        located.append(CaseError(message, file=file, line=line, column=col, field=format_path(at)))
    first = located[0]
    if len(located) == 1:
        return first
    return CaseError(first.reason + more_problems(len(located) - 1), file=file, line=first.line, column=first.column,
                     field=first.field, problems=located)


class LoadedCase:
    """A validated case together with where it came from (for readings files and messages)."""

    def __init__(self, case: Case, path: Path | None, marks: dict, allow_large: bool = False, until=None):
        self.case, self.path, self.marks = case, path, marks
        self.allow_large = allow_large  # meshes beyond the default size limit allowed (--allow-large)
        # readings up to a stage (its name) or a date (a datetime) only: `geoback update`; None: all
        self.until = until

    def with_case(self, case: Case) -> "LoadedCase":
        """The same origin (file, marks, allow_large, until) for a changed case (a finer mesh, a split layer)."""
        return LoadedCase(case, self.path, self.marks, allow_large=self.allow_large, until=self.until)

    def up_to(self, until) -> "LoadedCase":
        """The same case reading only the surveys up to `until` (a stage name or a datetime; None: all);
        instruments not read by then are left out of the fit (not yet installed or read)."""
        return LoadedCase(self.case, self.path, self.marks, allow_large=self.allow_large, until=until)

    @property
    def folder(self) -> Path:
        return self.path.parent if self.path else Path.cwd()

    def error(self, at: tuple, message: str) -> CaseError:
        line, col = locate(at, self.marks)
        return CaseError(message, file=str(self.path) if self.path else None, line=line, column=col,
                         field=format_path(at))

    def digest(self) -> str:
        text = json.dumps(self.case.model_dump(mode="json"), sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


def stage_names(case: Case) -> list[str]:
    """Names of the construction stages readings can be taken at, in construction order
    (the case's construction section; 'excavation' without one)."""
    from geoback.case.construction import stage_names as names

    return names(case)


def load_case(path: str | Path, allow_large: bool = False) -> LoadedCase:
    """Read and validate a case file (YAML). A case whose mesh is estimated beyond the default size
    limit (geoback.case.meshsize.max_dofs()) is refused unless `allow_large`, which the loaded case then
    carries to wherever it is meshed."""
    data, marks = load_yaml_with_marks(path)
    case = case_from_data(data, marks, file=str(path), allow_large=allow_large)
    return LoadedCase(case, Path(path), marks, allow_large=allow_large)


def case_schema() -> dict:
    """JSON Schema of the case file, for editors."""
    schema = Case.model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "geoback case"
    return schema
