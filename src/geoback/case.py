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

from .case_checks import physical_problems
from .case_messages import _clean_loc, _more, _pick
from .case_schema import (Case, Convergence, Deflectometer, FitSettings, Geometry, Ground,  # noqa: F401 (re-exported)
                          Inclinometer, Instrument, Layer, MeshSettings, Output, Parameter, PointsInstrument,
                          Prior, SlidingMicrometer, _show)
from .errors import CaseError
from .yamlmarks import format_path, load_yaml_with_marks, locate


def case_from_data(data: Any, marks: dict | None = None, file: str | None = None) -> Case:
    """Validate already-parsed data; raise CaseError located in the file."""
    marks = marks or {}
    if not isinstance(data, dict):
        line, col = marks.get((), (1, 1))
        raise CaseError(f"expected a mapping of case fields (name:, geometry:, ground:, ...), found {_show(data)}",
                        file=file, line=line, column=col, field=format_path(()))
    try:
        case = Case.model_validate(data)
    except ValidationError as exc:
        try:
            at, message, more = _pick(exc.errors(), data, marks)
        except Exception:  # pragma: no cover - the plain pydantic wording is better than a crash
            err = exc.errors()[0]
            at = _clean_loc(tuple(err["loc"]), data)
            message, more = err["msg"].replace("Input should be", "expected"), len(exc.errors()) - 1
        line, col = locate(at, marks)
        raise CaseError(message + _more(more), file=file, line=line, column=col,
                        field=format_path(at)) from None
    problems = physical_problems(case)
    if problems:
        at, message = problems[0]
        line, col = locate(at, marks)
        raise CaseError(message + _more(len(problems) - 1), file=file, line=line, column=col,
                        field=format_path(at))
    return case


class LoadedCase:
    """A validated case together with where it came from (for readings files and messages)."""

    def __init__(self, case: Case, path: Path | None, marks: dict):
        self.case, self.path, self.marks = case, path, marks

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
    from .construction import stage_names as names

    return names(case)


def load_case(path: str | Path) -> LoadedCase:
    """Read and validate a case file (YAML)."""
    data, marks = load_yaml_with_marks(path)
    case = case_from_data(data, marks, file=str(path))
    return LoadedCase(case, Path(path), marks)


def case_schema() -> dict:
    """JSON Schema of the case file, for editors."""
    schema = Case.model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "geoback case"
    return schema
