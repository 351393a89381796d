"""YAML loading that remembers where every value stood (line, column) in the file."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from .errors import CaseError

Path_ = tuple  # a field path: keys (str) and list indices (int)


def load_yaml_with_marks(path: str | Path) -> tuple[Any, dict[Path_, tuple[int, int]]]:
    """Parse a YAML file; return the data and a map field-path -> (line, column), 1-based.

    Duplicate keys are rejected (plain YAML silently keeps the last one).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise CaseError("file not found", file=str(path)) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CaseError(f"cannot read the file ({exc})", file=str(path)) from None
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        problem = getattr(exc, "problem", None) or str(exc)
        raise CaseError(f"invalid YAML: {problem}", file=str(path),
                        line=mark.line + 1 if mark else None,
                        column=mark.column + 1 if mark else None) from None
    if node is None:
        raise CaseError("the file is empty; expected a YAML mapping", file=str(path), line=1)
    marks: dict[Path_, tuple[int, int]] = {}
    loader = yaml.SafeLoader("")
    data = _construct(node, (), marks, loader, str(path))
    return data, marks


def _construct(node, at: Path_, marks, loader, file):
    marks[at] = (node.start_mark.line + 1, node.start_mark.column + 1)
    if isinstance(node, yaml.MappingNode):
        out = {}
        for key_node, value_node in node.value:
            key = loader.construct_object(key_node, deep=True)
            if key in out:
                raise CaseError(f"duplicate key '{key}'", file=file,
                                line=key_node.start_mark.line + 1,
                                column=key_node.start_mark.column + 1,
                                field=format_path(at + (key,)))
            out[key] = _construct(value_node, at + (key,), marks, loader, file)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_construct(v, at + (i,), marks, loader, file) for i, v in enumerate(node.value)]
    try:
        return loader.construct_object(node, deep=True)
    except yaml.YAMLError as exc:  # pragma: no cover - exotic tags
        raise CaseError(f"invalid YAML value: {exc}", file=file, line=marks[at][0],
                        column=marks[at][1], field=format_path(at)) from None


def format_path(at: Path_) -> str:
    """('instruments', 0, 'radius') -> 'instruments[0].radius'."""
    text = ""
    for part in at:
        if isinstance(part, int):
            text += f"[{part}]"
        else:
            text += ("." if text else "") + str(part)
    return text or "(top level)"


def locate(at: Path_, marks: dict[Path_, tuple[int, int]]) -> tuple[int | None, int | None]:
    """Line and column of the longest prefix of `at` that exists in the file."""
    for n in range(len(at), -1, -1):
        if at[:n] in marks:
            return marks[at[:n]]
    return None, None
