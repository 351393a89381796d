"""YAML syntax errors in plain words, located at a line and, where it can be found, at the field
path of the value standing there (``yamlmarks`` loads; this module explains what it cannot load)."""
from __future__ import annotations

from typing import Any

import yaml

from geoback.errors import CaseError

Path_ = tuple  # a field path: keys (str) and list indices (int)


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


def syntax_error(text: str, exc: yaml.YAMLError, file: str | None) -> CaseError:
    """One located line for a YAML syntax error, in plain words."""
    if isinstance(exc, yaml.reader.ReaderError):
        line = text[:exc.position].count("\n") + 1
        column = exc.position - (text.rfind("\n", 0, exc.position) + 1) + 1
        char = exc.character
        code = f"#x{char:04x}" if isinstance(char, int) else (f"#x{ord(char):04x}" if isinstance(char, str) and len(char) == 1 else "?")
        try:  # the path of a value standing where the character is
            from types import SimpleNamespace

            field = path_at_error(text[:exc.position] + "x", None, False,
                                   stop=SimpleNamespace(line=line - 1, column=column - 1))
        except Exception:  # noqa: BLE001 - the field is a courtesy
            field = None
        return CaseError(f"invalid YAML: expected printable text, found the control character {code}",
                         file=file, line=line, column=column, field=format_path(field or ()))
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
    field = path_at_error(text, mark, use_context)
    if field is None and mark is not None:  # e.g. the composer's errors: the path of what stands there
        field = path_at_error(text, None, False, stop=mark)
    field = field if field is not None else ()  # nothing open yet: the file as a whole
    return CaseError(f"invalid YAML: {message}", file=file,
                     line=mark.line + 1 if mark is not None else None,
                     column=mark.column + 1 if mark is not None else None,
                     field=format_path(field))


def path_at_error(text: str, mark, use_context: bool, stop=None, loader=yaml.SafeLoader) -> Path_ | None:
    """Field path being parsed when the syntax error struck (best effort, from the event stream);
    with `stop`, the path of the value that starts at that mark."""
    frames: list[dict] = []

    def done() -> None:
        if frames:
            f = frames[-1]
            if f["kind"] == "map":
                f["expect_key"] = True
            else:
                f["count"] += 1

    try:
        for ev in yaml.parse(text, Loader=loader):
            if stop is not None and (ev.start_mark.line, ev.start_mark.column) >= (stop.line, stop.column):
                break
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
    """('instruments', 0, 'radius') -> 'instruments[0].radius'; a key that could be misread in
    the path (containing ':', '.', brackets, quotes or spaces, or empty) is put in double quotes."""
    text = ""
    for part in at:
        if isinstance(part, int) and not isinstance(part, bool):
            text += f"[{part}]"
        else:
            key = printable(part)
            if not key or any(c in key for c in ':.[]" ') or key != key.strip():
                key = '"' + key.replace('"', '\\"') + '"'
            text += ("." if text else "") + key
    return text or "(top level)"
