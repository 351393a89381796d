"""Pydantic's validation errors rewritten for people: the field path as in the file, what was
expected and what was found, one line."""
from __future__ import annotations

import difflib
from typing import Any

from geoback.case.schema import (PARAMETER_NAME, Case, Construction, Convergence, Deflectometer, ErrorScale, FitSettings,
                          Geometry, Ground, Inclinometer, Layer, Lining, MeshSettings, Output, Parameter,
                          PointsInstrument, Prior, ScalePrior, SlidingMicrometer, Stage, number_text, shown)
from geoback.case.yamlmarks import locate, printable


# ---------------------------------------------------------------------------- schema errors
_KINDS = {"points": PointsInstrument, "inclinometer": Inclinometer, "sliding_micrometer": SlidingMicrometer,
          "extensometer": SlidingMicrometer, "deflectometer": Deflectometer, "convergence": Convergence}
_CHILDREN: dict = {Case: {"geometry": Geometry, "ground": Ground, "mesh": MeshSettings, "instruments": "instrument",
                          "parameters": Parameter, "fit": FitSettings, "output": Output,
                          "error_scales": ErrorScale, "construction": Construction},
                   Ground: {"layers": Layer}, Parameter: {"prior": Prior}, ErrorScale: {"prior": ScalePrior},
                   Construction: {"lining": Lining, "stages": Stage}}
_PATTERNS = {r"^[A-Za-z0-9_\-.]+$": "a name of letters, digits, '_', '-' or '.' (no spaces)",
             r"^[A-Za-z_][A-Za-z0-9_\-]*$": "a name starting with a letter or '_', then letters, digits, '_' or '-'",
             PARAMETER_NAME:
                 "a parameter name such as E, K0, E[layer] or B[instrument]"}
_PAIRS = {"start": "[x, y]", "end": "[x, y]", "bounds": "[lower, upper]"}


def _model_at(at: tuple, data: Any):
    """The model class describing the mapping at path `at` of the data (None if unknown)."""
    model, node = Case, data
    for part in at:
        if isinstance(part, int):
            node = node[part] if isinstance(node, list) and 0 <= part < len(node) else None
            continue
        if model == "instrument":
            model = _instrument_model(node)
        model = _CHILDREN.get(model, {}).get(part)
        if model is None:
            return None
        node = node.get(part) if isinstance(node, dict) else None
    if model == "instrument":
        model = _instrument_model(node)
    return model


def _instrument_model(node: Any):
    kind = node.get("kind") if isinstance(node, dict) else None
    return _KINDS.get(kind) if isinstance(kind, str) else None


def clean_loc(loc: tuple, data: Any) -> tuple:
    """Drop the union tags pydantic inserts (e.g. 'inclinometer') so the path follows the file."""
    out: list = []
    for k, part in enumerate(loc):
        if (k == 2 and loc[0] == "instruments" or k == 3 and loc[:2] == ("design", "candidates")) and part in _KINDS:
            continue  # the discriminated union's tag (of an instrument, or of a design's candidate)
        if isinstance(part, str) and ("[" in part or part.startswith(("function-", "tagged-union"))):
            continue  # a validator's tag such as 'function-after[...]'
        if part in ("in-order", "by-stage") and out and out[-1] == "readings":
            continue  # the two shapes of readings (case_schema.Readings)
        if part in ("circular", "layout") and out == ["geometry"]:
            continue  # the two geometries (a circular tunnel's, a section with openings)
        if part in ("circle", "horseshoe", "polygon") and len(out) >= 3 and out[-2] == "openings":
            continue  # an opening's shape
        out.append(part)
    return tuple(out)


def _fields_text(model) -> str:
    names = list(model.model_fields)
    if model in _KINDS.values():
        names.remove("kind")
        names.insert(0, "kind")
    return ", ".join(names)


def _bound(v: Any) -> str:
    return number_text(v) if isinstance(v, (int, float)) else str(v)


def _expected(err: dict, at: tuple, data: Any) -> str:
    """The 'expected ...' phrase of a pydantic error, in plain words."""
    t, ctx = err["type"], err.get("ctx") or {}
    simple = {"float_type": "a number", "float_parsing": "a number", "int_type": "a whole number",
              "int_parsing": "a whole number", "int_from_float": "a whole number", "string_type": "text",
              "bool_type": "true or false", "bool_parsing": "true or false", "list_type": "a list",
              "finite_number": "a finite number", "dict_type": "a mapping of fields"}
    if t in simple:
        return simple[t]
    if t == "greater_than":
        return f"a number greater than {_bound(ctx['gt'])}"
    if t == "greater_than_equal":
        return f"a number of at least {_bound(ctx['ge'])}"
    if t == "less_than":
        return f"a number less than {_bound(ctx['lt'])}"
    if t == "less_than_equal":
        return f"a number of at most {_bound(ctx['le'])}"
    if t == "literal_error":
        return f"one of {ctx.get('expected', '?')}"
    if t in ("model_type", "model_attributes_type"):
        model = _model_at(at, data)
        return f"a mapping of fields ({_fields_text(model)})" if model else "a mapping of fields"
    if t == "string_pattern_mismatch":
        return _PATTERNS.get(ctx.get("pattern"), f"text matching {ctx.get('pattern')}")
    if t in ("tuple_type", "too_long", "too_short") and at and at[-1] in _PAIRS:
        return f"2 values {_PAIRS[at[-1]]}"
    if t == "too_short":
        n = ctx.get("min_length", 1)
        return f"at least {n} item{'s' if n != 1 else ''}"
    if t == "too_long":
        n = ctx.get("max_length", 1)
        return f"at most {n} item{'s' if n != 1 else ''}"
    if t == "tuple_type":
        return "a list"
    msg = err["msg"]
    for prefix in ("Input should be ", "Value should be "):
        if msg.startswith(prefix):
            return msg[len(prefix):]
    return msg[0].lower() + msg[1:]


def _field_info(at: tuple, data: Any):
    if not at or not isinstance(at[-1], str):
        return None
    model = _model_at(at[:-1], data)
    return model.model_fields.get(at[-1]) if model else None


def _is_pair(at: tuple, data: Any) -> bool:
    """Is the value at `at` one of the schema's 2-tuples ([x, y], [lower, upper], convergence points)?"""
    if not at:
        return False
    if at[-1] in _PAIRS:
        return True
    if len(at) >= 2 and at[-2] == "points" and isinstance(at[-1], int):
        return True  # a point [x, y] of a points list
    if at[-1] == "points" and _model_at(at[:-1], data) is Convergence:
        return True
    return False


def _describe(err: dict, data: Any) -> tuple[tuple, str]:
    """(path, message) for one pydantic error: what was expected and what was found."""
    t, ctx = err["type"], err.get("ctx") or {}
    at = clean_loc(tuple(err["loc"]), data)
    found = err.get("input")
    if t == "missing" and at and isinstance(at[-1], int):  # a pair given too few values
        pair = at[:-1]
        what = _PAIRS.get(pair[-1], "[x, y]") if pair else "[x, y]"
        if pair and pair[-1] == "points" and _model_at(pair[:-1], data) is Convergence:
            what = "points [[x1, y1], [x2, y2]]"
        return pair, f"expected 2 {what if what.startswith('points') else 'values ' + what}, found {shown(found)}"
    if t == "missing":
        field = _field_info(at, data)
        what = f" ({field.description})" if field is not None and field.description else ""
        have = ", ".join(printable(k) for k in found) if isinstance(found, dict) and found else "no fields"
        return at, f"expected the required field '{at[-1]}'{what}, found it missing (given: {have})"
    if t == "extra_forbidden":
        key = printable(at[-1])
        model = _model_at(at[:-1], data)
        allowed = _fields_text(model) if model else ""
        close = difflib.get_close_matches(key, list(model.model_fields) if model else [], n=1, cutoff=0.6)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        return at, (f"unknown field '{key}'{hint}: expected one of {allowed}" if allowed
                    else f"unknown field '{key}'{hint}")
    if t == "union_tag_invalid":
        kinds = ", ".join(_KINDS)
        return at + ("kind",), f"unknown instrument kind {shown(ctx.get('tag'))}: expected one of {kinds}"
    if t == "union_tag_not_found":
        kinds = ", ".join(_KINDS)
        if isinstance(found, dict):
            return at + ("kind",), f"expected the required field 'kind' (one of {kinds}), found it missing"
        return at, f"expected a mapping describing an instrument (kind: one of {kinds}), found {shown(found)}"
    if t in ("value_error", "assertion_error"):
        msg = err["msg"].removeprefix("Value error, ").removeprefix("Assertion failed, ")
        if "found" not in msg and not isinstance(found, dict):
            msg += f", found {shown(found)}"
        return at, msg
    if t in ("too_short", "too_long") or (t == "tuple_type" and _is_pair(at, data)):
        if _is_pair(at, data) and t != "too_short":
            what = "2 points [[x1, y1], [x2, y2]]" if at[-1] == "points" else \
                f"2 values {_PAIRS.get(at[-1], '[x, y]')}"
            n = ctx.get("actual_length")
            got = f"{n} value{'s' if n != 1 else ''}" if n is not None else shown(found)
            return at, f"expected {what}, found {got}"
        n = ctx.get("actual_length")
        got = f"{n} item{'s' if n != 1 else ''}" if n is not None else shown(found)
        return at, f"expected {_expected(err, at, data)}, found {got}"
    if t == "string_type" and isinstance(found, (int, float)) and not isinstance(found, bool):
        return at, f"expected text, found the number {shown(found)} (put it in quotes)"
    return at, f"expected {_expected(err, at, data)}, found {shown(found)}"


def described_problems(errors: list[dict], data: Any, marks: dict) -> list[tuple[tuple, str]]:
    """Every problem pydantic found, as (path, message), in file order; a misspelt key once."""
    described = [_describe(e, data) + (e,) for e in errors]
    # a misspelt key shows up twice: unknown 'radus' and missing 'radius'. Report it once.
    typos = set()
    for at, msg, e in described:
        if e["type"] == "extra_forbidden" and "did you mean '" in msg:
            typos.add(at[:-1] + (msg.split("did you mean '")[1].split("'")[0],))
    described = [d for d in described if not (d[2]["type"] == "missing" and d[0] in typos)]

    def order(d):
        at, _, e = d
        line, col = locate(at, marks)
        return (line if line is not None else 0, col if col is not None else 0)

    described.sort(key=order)
    out: list[tuple[tuple, str]] = []
    for at, msg, _ in described:
        if (at, msg) not in out:
            out.append((at, msg))
    return out


def _pick(errors: list[dict], data: Any, marks: dict) -> tuple[tuple, str, int]:
    """The error to report (first in the file; a misspelt key before the field it misses) and how many
    other problems there are."""
    described = described_problems(errors, data, marks)
    at, msg = described[0]
    return at, msg, len(described) - 1


def more_problems(n: int) -> str:
    return f" (and {n} more problem{'s' if n > 1 else ''})" if n else ""
