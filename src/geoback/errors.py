"""Errors that geoback explains to the user instead of crashing on."""
from __future__ import annotations


class GeobackError(Exception):
    """Base of every error geoback answers with a message and exit code 2."""

    exit_code = 2


class CaseError(GeobackError):
    """A mistake in a case file, located by file, line, column and field path.

    ``problems`` lists every problem found (each a CaseError with one located message; the
    error itself when there is only one): the message of the error is the first of them with
    "(and N more problems)", and `geoback validate` prints them all, one per line.
    """

    def __init__(self, message: str, file: str | None = None, line: int | None = None,
                 column: int | None = None, field: str | None = None,
                 problems: "list[CaseError] | None" = None):
        self.file, self.line, self.column, self.field = file, line, column, field
        self.reason = message
        self.problems: list[CaseError] = list(problems) if problems else [self]
        where = ""
        if file:
            where = str(file)
            if line is not None:
                where += f":{line}"
                if column is not None:
                    where += f":{column}"
            where += ": "
        what = f"{field}: " if field else ""
        super().__init__(f"{where}{what}{message}")


class ForwardFailure(GeobackError):
    """The model could not be solved at the values asked (a non-linear forward run that did not
    converge, a state outside what the model admits). Inside a fit, a trial point where this
    happens is a rejected step (``estimate.fit``); elsewhere it is reported like any other error."""


class TimeLimit(GeobackError):
    """The wall-clock limit of a command (``--time-limit``, ``geoback.case.budget``) passed in work that
    could not stop early with a result; the message says where the work was. Exit code 1: the input
    was not refused, the work was cut short."""

    exit_code = 1
