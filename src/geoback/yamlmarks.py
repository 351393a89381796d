"""YAML loading that remembers where every value stood (line, column) in the file.

``marks`` maps a field path (keys and list indices) to a 1-based (line, column): where the
value stands, except for a value that is a block mapping or block list spanning several lines,
which is located at its key (``geometry:``) so that a message about the whole block points at
the line that names it.
"""
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
    except IsADirectoryError:
        raise CaseError("expected a case file (YAML), found a directory", file=str(path)) from None
    except UnicodeDecodeError as exc:
        line = exc.object[:exc.start].count(b"\n") + 1 if isinstance(exc.object, bytes) else None
        raise CaseError(f"expected a UTF-8 text file, found the byte 0x{exc.object[exc.start]:02x} "
                        f"(is it a YAML file?)", file=str(path), line=line) from None
    except OSError as exc:
        raise CaseError(f"cannot read the file ({exc.strerror or exc})", file=str(path)) from None
    return parse_yaml_with_marks(text, str(path))


def parse_yaml_with_marks(text: str, file: str | None = None) -> tuple[Any, dict[Path_, tuple[int, int]]]:
    """As load_yaml_with_marks, for text already read (``file`` only names it in messages)."""
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as exc:
        raise _syntax_error(text, exc, file) from None
    except RecursionError:
        raise CaseError("invalid YAML: the file nests too deeply", file=file) from None
    if node is None:
        raise CaseError("expected a YAML mapping of case fields (name:, geometry:, ground:, ...), "
                        "found an empty file", file=file, line=1, column=1, field=format_path(()))
    marks: dict[Path_, tuple[int, int]] = {}
    loader = yaml.SafeLoader("")
    data = _construct(node, (), marks, loader, file, _mark(node), set())
    return data, marks


def _mark(node) -> tuple[int, int]:
    return node.start_mark.line + 1, node.start_mark.column + 1


def _is_block(node) -> bool:
    return isinstance(node, (yaml.MappingNode, yaml.SequenceNode)) and not node.flow_style \
        and node.start_mark.line != node.end_mark.line


def _construct(node, at: Path_, marks, loader, file, mark, active: set):
    marks[at] = mark
    if isinstance(node, (yaml.MappingNode, yaml.SequenceNode)):
        if id(node) in active:
            raise CaseError("invalid YAML: an alias refers to a node that contains it (a cycle)",
                            file=file, line=mark[0], column=mark[1], field=format_path(at))
        active = active | {id(node)}
    if isinstance(node, yaml.MappingNode):
        try:
            loader.flatten_mapping(node)  # YAML merge keys (<<: *anchor)
        except yaml.YAMLError as exc:
            raise CaseError(f"invalid YAML merge: {getattr(exc, 'problem', None) or exc}", file=file,
                            line=mark[0], column=mark[1], field=format_path(at)) from None
        out = {}
        for key_node, value_node in node.value:
            key_mark = _mark(key_node)
            if not isinstance(key_node, yaml.ScalarNode):
                raise CaseError("expected a plain name as a key, found a "
                                f"{'list' if isinstance(key_node, yaml.SequenceNode) else 'mapping'}",
                                file=file, line=key_mark[0], column=key_mark[1], field=format_path(at))
            try:
                key = loader.construct_object(key_node, deep=True)
            except yaml.YAMLError as exc:
                raise CaseError(f"invalid YAML key: {getattr(exc, 'problem', None) or exc}", file=file,
                                line=key_mark[0], column=key_mark[1], field=format_path(at)) from None
            if not isinstance(key, str):
                key = key_node.value  # `null:`, `yes:`, `1:` are names here, as written
            if key in out:
                first = marks.get(at + (key,))
                raise CaseError(f"duplicate key '{printable(key)}': expected each key once per mapping, found it again"
                                + (f" (first on line {first[0]})" if first else ""),
                                file=file, line=key_mark[0], column=key_mark[1],
                                field=format_path(at + (key,)))
            out[key] = _construct(value_node, at + (key,), marks, loader, file,
                                  key_mark if _is_block(value_node) else _mark(value_node), active)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_construct(v, at + (i,), marks, loader, file, _mark(v), active)
                for i, v in enumerate(node.value)]
    try:
        return loader.construct_object(node, deep=True)
    except yaml.YAMLError as exc:
        raise CaseError(f"invalid YAML value: {getattr(exc, 'problem', None) or exc}", file=file,
                        line=mark[0], column=mark[1], field=format_path(at)) from None


# ---------------------------------------------------------------------------- syntax errors
_TOKENS = {"<block mapping start>": "a key indented differently from the lines above",
           "<block sequence start>": "a list indented differently from the lines above",
           "<block end>": "the end of an indented block",
           "<stream end>": "the end of the file",
           "end of stream": "the end of the file",
           "<scalar>": "more text (a ',' missing?)",
           "<document start>": "'---'",
           "'?'": "a line not indented like the ones above",
           "'-'": "a list item '-' where a 'key: value' was expected"}


def _found(token: str) -> str:
    token = token.strip()
    return _TOKENS.get(token, _TOKENS.get(token.strip("'"), token))


def _syntax_error(text: str, exc: yaml.YAMLError, file: str | None) -> CaseError:
    """One located line for a YAML syntax error, in plain words."""
    if isinstance(exc, yaml.reader.ReaderError):
        line = text[:exc.position].count("\n") + 1
        column = exc.position - (text.rfind("\n", 0, exc.position) + 1) + 1
        char = exc.character
        code = f"#x{char:04x}" if isinstance(char, int) else (f"#x{ord(char):04x}" if isinstance(char, str) and len(char) == 1 else "?")
        return CaseError(f"invalid YAML: expected printable text, found the control character {code}",
                         file=file, line=line, column=column)
    problem = (getattr(exc, "problem", None) or "").strip()
    context = (getattr(exc, "context", None) or "").strip()
    pmark, cmark = getattr(exc, "problem_mark", None), getattr(exc, "context_mark", None)
    use_context = cmark is not None and any(
        w in context for w in ("flow sequence", "flow mapping", "quoted scalar", "simple key", "block scalar",
                               "directive", "anchor", "alias", "tag"))
    mark = cmark if use_context else (pmark or cmark)
    where = f" on line {pmark.line + 1}" if pmark is not None and mark is not pmark else ""
    head, _, tail = problem.partition(", but found ")
    if not tail:
        head, _, tail = problem.partition(", but got ")
    quote = " (put text containing [ ] { } , or : in quotes)" if tail.strip("'") in "[]{},:" else ""
    if "flow sequence" in context:
        message = f"the list opened with '[' here is not closed: expected ',' or ']', found {_found(tail)}{where}{quote}"
    elif "flow mapping" in context:
        message = f"the mapping opened with '{{' here is not closed: expected ',' or '}}', found {_found(tail)}{where}{quote}"
    elif "quoted scalar" in context:
        message = f"the quoted text opened here is not closed: expected a closing quote, found {_found(problem.removeprefix('found unexpected '))}{where}"
    elif "simple key" in context:
        message = f"expected ':' after the key on this line, found {_found(problem.removeprefix('could not find expected '))}{where}"
    elif problem == "mapping values are not allowed here":
        message = ("expected one 'key: value' per line, found another ':' (indent nested keys under their "
                   "parent's name, or quote a value that contains ': ')")
    elif "cannot start any token" in problem and "\\t" in problem:
        message = "expected spaces for indentation, found a tab character"
    elif tail and head.startswith("expected"):
        message = f"{head}, found {_found(tail)}"
        if "block" in context:
            message = (f"expected the next 'key: value' (or '- item') indented like the lines above it, "
                       f"found {_found(tail)}")
    elif "another document" in problem:
        message = "expected a single YAML document, found a second one ('---')"
    else:
        message = problem or str(exc).splitlines()[0]
        if context and cmark is not None and mark is not cmark:
            message += f" ({context} on line {cmark.line + 1})"
    field = _path_at_error(text, mark, use_context)
    return CaseError(f"invalid YAML: {message}", file=file,
                     line=mark.line + 1 if mark is not None else None,
                     column=mark.column + 1 if mark is not None else None,
                     field=format_path(field) if field is not None else None)


def _path_at_error(text: str, mark, use_context: bool) -> Path_ | None:
    """Field path being parsed when the syntax error struck (best effort, from the event stream)."""
    frames: list[dict] = []

    def done() -> None:
        if frames:
            f = frames[-1]
            if f["kind"] == "map":
                f["expect_key"] = True
            else:
                f["count"] += 1

    try:
        for ev in yaml.parse(text, Loader=yaml.SafeLoader):
            if isinstance(ev, (yaml.MappingStartEvent, yaml.SequenceStartEvent, yaml.ScalarEvent,
                               yaml.AliasEvent)):
                path: Path_ = ()
                if frames:
                    f = frames[-1]
                    if f["kind"] == "map":
                        if f["expect_key"]:
                            if not isinstance(ev, yaml.ScalarEvent):
                                return None  # a complex key: give up
                            f["key"], f["expect_key"] = ev.value, False
                            continue
                        path = f["path"] + (f["key"],)
                    else:
                        path = f["path"] + (f["count"],)
                if isinstance(ev, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
                    frames.append({"kind": "map" if isinstance(ev, yaml.MappingStartEvent) else "seq",
                                   "path": path, "mark": (ev.start_mark.line, ev.start_mark.column),
                                   "key": None, "expect_key": True, "count": 0})
                else:
                    done()
            elif isinstance(ev, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
                if frames:
                    frames.pop()
                done()
    except yaml.YAMLError:
        pass
    except RecursionError:  # pragma: no cover
        return None
    if mark is not None and use_context:
        for f in frames:
            if f["mark"] == (mark.line, mark.column):
                return f["path"]
    if not frames:
        return None
    f = frames[-1]
    if f["kind"] == "map" and not f["expect_key"]:
        return f["path"] + (f["key"],)
    return f["path"]


def printable(text: Any) -> str:
    """Text safe for a one-line message: control characters and line breaks escaped."""
    text = str(text)
    return text if text.isprintable() else repr(text)[1:-1]


def format_path(at: Path_) -> str:
    """('instruments', 0, 'radius') -> 'instruments[0].radius'."""
    text = ""
    for part in at:
        if isinstance(part, int) and not isinstance(part, bool):
            text += f"[{part}]"
        else:
            text += ("." if text else "") + printable(part)
    return text or "(top level)"


def locate(at: Path_, marks: dict[Path_, tuple[int, int]]) -> tuple[int | None, int | None]:
    """Line and column of the longest prefix of `at` that exists in the file."""
    for n in range(len(at), -1, -1):
        if at[:n] in marks:
            return marks[at[:n]]
    return None, None
