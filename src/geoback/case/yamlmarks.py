"""YAML loading that remembers where every value stood (line, column) in the file.

``marks`` maps a field path (keys and list indices) to a 1-based (line, column): where the
value stands, except for a value that is a block mapping or block list spanning several lines,
which is located at its key (``geometry:``) so that a message about the whole block points at
the line that names it.

The work is bounded whatever the file holds: at most ``MAX_BYTES`` of text, ``MAX_NODES``
values composed and constructed (each use of an alias counts again), ``MAX_ALIAS_NODES`` of
them produced through aliases (so a 400-byte "billion laughs" file is refused at once, not
after minutes and gigabytes), and ``MAX_DEPTH`` levels of nesting. A case file needs a few
hundred values; the limits leave room for inline readings of many long instruments.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml
from yaml.composer import Composer
from yaml.constructor import SafeConstructor
from yaml.resolver import Resolver

from geoback.errors import CaseError
from geoback.case.yaml_errors import format_path, path_at_error, printable, syntax_error  # noqa: F401 (re-exported)

Path_ = tuple  # a field path: keys (str) and list indices (int)

MAX_BYTES = 5_000_000  # size of a case file
MAX_NODES = 50_000  # values (scalars, lists, mappings) composed, and constructed counting alias reuse
MAX_ALIAS_NODES = 10_000  # values produced by expanding aliases (*name) and merge keys (<<: *name)
MAX_DEPTH = 64  # nesting levels (a case nests about 5)


class _Limit(Exception):
    def __init__(self, what: str, mark):
        self.what, self.mark = what, mark


class _BoundedComposer(Composer):
    """pyyaml's composer, counting nodes and nesting as it goes."""

    def _bounded_init(self) -> None:
        Composer.__init__(self)
        self._nodes = 0
        self._depth = 0

    def compose_node(self, parent, index):
        self._depth += 1
        if self._depth > MAX_DEPTH:
            raise _Limit("depth", self.peek_event().start_mark)
        try:
            node = super().compose_node(parent, index)
        finally:
            self._depth -= 1
        self._nodes += 1
        if self._nodes > MAX_NODES:
            raise _Limit("nodes", node.start_mark)
        return node


class _PyLoader(yaml.reader.Reader, yaml.scanner.Scanner, yaml.parser.Parser, _BoundedComposer,
                SafeConstructor, Resolver):
    """Pure-Python parsing (pyyaml's messages, which _syntax_error puts in plain words)."""

    def __init__(self, stream):
        yaml.reader.Reader.__init__(self, stream)
        yaml.scanner.Scanner.__init__(self)
        yaml.parser.Parser.__init__(self)
        self._bounded_init()
        SafeConstructor.__init__(self)
        Resolver.__init__(self)


try:  # libyaml's parser (about 6x faster) feeding the same Python composer
    from yaml._yaml import CParser

    class _CLoader(_BoundedComposer, CParser, SafeConstructor, Resolver):
        def __init__(self, stream):
            CParser.__init__(self, stream)
            self._bounded_init()
            SafeConstructor.__init__(self)
            Resolver.__init__(self)
except ImportError:  # pragma: no cover - pyyaml built without libyaml
    _CLoader = None


def _compose(text: str):
    """The document's node graph (aliases not expanded). A syntax error is reported with the
    pure-Python parser's wording whichever parser found it."""
    if _CLoader is not None:
        loader = _CLoader(text)
        try:
            return loader.get_single_node()
        except yaml.YAMLError:
            pass  # parse again below for pyyaml's own message (and its view of what is valid)
        finally:
            loader.dispose()
    loader = _PyLoader(text)
    try:
        return loader.get_single_node()
    finally:
        loader.dispose()


def load_yaml_with_marks(path: str | Path) -> tuple[Any, dict[Path_, tuple[int, int]]]:
    """Parse a YAML file; return the data and a map field-path -> (line, column), 1-based.

    Duplicate keys are rejected (plain YAML silently keeps the last one).
    """
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            raw = fh.read(MAX_BYTES + 1)
        if len(raw) > MAX_BYTES:
            size = path.stat().st_size
            raise CaseError(f"expected a case file of at most {MAX_BYTES / 1e6:g} MB, found {size / 1e6:.3g} MB "
                            f"(long readings belong in a readings_file CSV)", file=str(path))
        text = raw.decode("utf-8")
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
    if len(text) > MAX_BYTES:
        raise CaseError(f"expected a case file of at most {MAX_BYTES / 1e6:g} MB, found {len(text) / 1e6:.3g} MB "
                        f"(long readings belong in a readings_file CSV)", file=file)
    try:
        node = _compose(text)
    except yaml.YAMLError as exc:
        raise syntax_error(text, exc, file) from None
    except _Limit as limit:
        raise _limit_error(text, limit, file) from None
    except RecursionError:  # pragma: no cover - MAX_DEPTH stops nesting long before
        raise CaseError("invalid YAML: the file nests too deeply", file=file) from None
    if node is None:
        raise CaseError("expected a YAML mapping of case fields (name:, geometry:, ground:, ...), "
                        "found an empty file", file=file, line=1, column=1, field=format_path(()))
    marks: dict[Path_, tuple[int, int]] = {}
    loader = yaml.SafeLoader("")
    budget = _Budget()
    data = _construct(node, (), marks, loader, file, _mark(node), set(), budget)
    return data, marks


class _Budget:
    """Nodes constructed so far, and those reached again through an alias or a merge key."""

    def __init__(self):
        self.nodes = 0
        self.via_alias = 0
        self.seen: set[int] = set()


def _limit_error(text: str, limit: _Limit, file: str | None) -> CaseError:
    mark = limit.mark
    if limit.what == "depth":
        message = f"expected at most {MAX_DEPTH} levels of nested lists and mappings, found more"
    else:
        message = (f"expected at most {MAX_NODES:,} values in a case file, found more "
                   f"(long readings belong in a readings_file CSV)")
    try:
        field = path_at_error(text, None, False, stop=mark,
                               loader=yaml.CSafeLoader if _CLoader is not None else yaml.SafeLoader)
    except Exception:  # noqa: BLE001 - the location is a courtesy
        field = None
    return CaseError(message, file=file, line=mark.line + 1, column=mark.column + 1,
                     field=format_path(field) if field is not None else format_path(()))


def _mark(node) -> tuple[int, int]:
    return node.start_mark.line + 1, node.start_mark.column + 1


def _is_block(node) -> bool:
    return isinstance(node, (yaml.MappingNode, yaml.SequenceNode)) and not node.flow_style \
        and node.start_mark.line != node.end_mark.line


def _construct(node, at: Path_, marks, loader, file, mark, active: set, budget: _Budget):
    marks[at] = mark
    budget.nodes += 1
    again = id(node) in budget.seen
    if again:
        budget.via_alias += 1
    else:
        budget.seen.add(id(node))
    if budget.nodes > MAX_NODES or budget.via_alias > MAX_ALIAS_NODES:
        line, column = _mark(node)
        if budget.via_alias > MAX_ALIAS_NODES:
            message = (f"expected aliases (*name) and merge keys (<<: *name) to repeat at most "
                       f"{MAX_ALIAS_NODES:,} values, found them expanding to more (anchors that refer to "
                       f"anchors multiply: an alias bomb?)")
        else:
            message = (f"expected at most {MAX_NODES:,} values in a case file (each use of an alias counted), "
                       f"found more (long readings belong in a readings_file CSV)")
        raise CaseError(message, file=file, line=line, column=column, field=format_path(at))
    if isinstance(node, (yaml.MappingNode, yaml.SequenceNode)):
        if id(node) in active:
            raise CaseError("invalid YAML: an alias refers to a node that contains it (a cycle)",
                            file=file, line=mark[0], column=mark[1], field=format_path(at))
        active = active | {id(node)}
    if isinstance(node, yaml.MappingNode):
        out = {}
        for key, key_node, value_node in _pairs(node, at, marks, loader, file, budget, active):
            key_mark = _mark(key_node)
            out[key] = _construct(value_node, at + (key,), marks, loader, file,
                                  key_mark if _is_block(value_node) else _mark(value_node), active, budget)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_construct(v, at + (i,), marks, loader, file, _mark(v), active, budget)
                for i, v in enumerate(node.value)]
    try:
        return loader.construct_object(node, deep=True)
    except yaml.YAMLError as exc:
        raise CaseError(f"invalid YAML value: {getattr(exc, 'problem', None) or exc}", file=file,
                        line=mark[0], column=mark[1], field=format_path(at)) from None
    except Exception:  # noqa: BLE001 - pyyaml's constructors raise plain errors on some tagged values
        raise CaseError(_bad_tagged(node), file=file, line=mark[0], column=mark[1], field=format_path(at)) from None


def _bad_tagged(node) -> str:
    tag = str(node.tag).rsplit(":", 1)[-1]
    return (f"invalid YAML value: expected a valid {printable(tag)} (as YAML reads this value), found "
            f"{printable(repr(node.value))[:60]} (put it in quotes to keep it as text)")


_MERGE = "tag:yaml.org,2002:merge"


def _key(key_node, at: Path_, loader, file) -> Any:
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
    except Exception:  # noqa: BLE001 - as for values
        raise CaseError(_bad_tagged(key_node).replace("value", "key", 1), file=file, line=key_mark[0],
                        column=key_mark[1], field=format_path(at)) from None
    if not isinstance(key, str):
        key = key_node.value  # `null:`, `yes:`, `1:` are names here, as written
    return key


def _pairs(node, at: Path_, marks, loader, file, budget: _Budget, active: set) -> list:
    """(key, key node, value node) of a mapping, YAML merge keys (``<<: *anchor`` or
    ``<<: [*a, *b]``) resolved as the spec says: the mapping's own keys override merged ones, and
    an earlier merged mapping overrides a later one. A key written twice in the same mapping is an
    error (plain YAML silently keeps the last one)."""
    own: dict = {}
    merged: list = []
    for key_node, value_node in node.value:
        if key_node.tag == _MERGE:
            sources = value_node.value if isinstance(value_node, yaml.SequenceNode) else [value_node]
            for source in sources:
                if not isinstance(source, yaml.MappingNode):
                    line, column = _mark(source)
                    raise CaseError("invalid YAML merge: expected a mapping (or a list of mappings) after '<<', "
                                    f"found a {'list' if isinstance(source, yaml.SequenceNode) else 'value'}",
                                    file=file, line=line, column=column, field=format_path(at))
                if id(source) in active or source is node:
                    line, column = _mark(source)
                    raise CaseError("invalid YAML: an alias refers to a node that contains it (a cycle)",
                                    file=file, line=line, column=column, field=format_path(at))
                budget.via_alias += len(source.value)  # the work a merge repeats
                if budget.via_alias > MAX_ALIAS_NODES:
                    line, column = _mark(source)
                    raise CaseError(f"expected aliases (*name) and merge keys (<<: *name) to repeat at most "
                                    f"{MAX_ALIAS_NODES:,} values, found them expanding to more (anchors that "
                                    f"refer to anchors multiply: an alias bomb?)",
                                    file=file, line=line, column=column, field=format_path(at))
                merged.append(_pairs(source, at, marks, loader, file, budget, active | {id(node)}))
            continue
        key = _key(key_node, at, loader, file)
        if key in own:
            first = _mark(own[key][0])
            key_mark = _mark(key_node)
            raise CaseError(f"duplicate key '{printable(key)}': expected each key once per mapping, found it again"
                            f" (first on line {first[0]})",
                            file=file, line=key_mark[0], column=key_mark[1], field=format_path(at + (key,)))
        own[key] = (key_node, value_node)
    if not merged:
        return [(k, kn, vn) for k, (kn, vn) in own.items()]
    out: dict = {}
    for pairs in merged:  # earlier merged mappings win over later ones
        for key, key_node, value_node in pairs:
            out.setdefault(key, (key_node, value_node))
    out.update(own)  # the mapping's own keys win over merged ones
    return [(k, kn, vn) for k, (kn, vn) in out.items()]


def locate(at: Path_, marks: dict[Path_, tuple[int, int]]) -> tuple[int | None, int | None]:
    """Line and column of the longest prefix of `at` that exists in the file."""
    for n in range(len(at), -1, -1):
        if at[:n] in marks:
            return marks[at[:n]]
    return None, None
