"""Measured readings of the case's instruments, inline or from CSV files, in survey order.

Primary readings of linewise instruments (slopes, length changes, curvatures) are integrated
into displacements with the constants taken as zero (eqns 11, 15, 18); both forms then give the
same objective (eqns 21-26).
"""
from __future__ import annotations

import csv

import numpy as np

from .case import LoadedCase
from .instruments import InstrumentBlock


def measured_values(loaded: LoadedCase, blocks: list[InstrumentBlock]) -> np.ndarray | None:
    """Every instrument's readings stacked in survey order; None if an instrument has none."""
    values = [instrument_readings(loaded.case.instruments[b.index], loaded, b) for b in blocks]
    if any(v is None for v in values):
        return None
    return np.concatenate(values)


def instrument_readings(ins, loaded: LoadedCase, block: InstrumentBlock) -> np.ndarray | None:
    index = block.index
    m = block.m
    if ins.readings is not None and ins.readings_file is not None:
        raise loaded.error(("instruments", index, "readings_file"), "give either 'readings' or 'readings_file', not both")
    if ins.readings is not None:
        values = np.asarray(ins.readings, float)
        at = ("instruments", index, "readings")
    elif ins.readings_file is not None:
        at = ("instruments", index, "readings_file")
        values = read_readings_csv(loaded.folder / ins.readings_file, ins.name, loaded, at)
    else:
        return None
    if len(values) != m:
        raise loaded.error(at, f"expected {m} readings for instrument '{ins.name}' "
                               f"({'stations' if block.integration is not None else 'point components'}), "
                               f"found {len(values)}")
    if not np.all(np.isfinite(values)):
        raise loaded.error(at, f"instrument '{ins.name}' has a NaN or infinite reading "
                               f"(reading {int(np.flatnonzero(~np.isfinite(values))[0]) + 1})")
    if block.reading_type == "primary":
        values = block.integration @ values  # eqns 11, 15, 18 with the constants taken as zero
    return values


def read_readings_csv(path, name: str, loaded: LoadedCase, at: tuple) -> np.ndarray:
    """Readings from CSV: a column 'reading' (or 'value'); rows of other instruments skipped
    when an 'instrument' column is present."""
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    except FileNotFoundError:
        raise loaded.error(at, f"readings file not found: {path}") from None
    if not rows:
        raise loaded.error(at, f"readings file {path} has no rows")
    column = next((c for c in ("reading", "value", "measured") if c in rows[0]), None)
    if column is None:
        raise loaded.error(at, f"readings file {path} needs a column named 'reading' (found {list(rows[0])})")
    if "instrument" in rows[0]:
        rows = [r for r in rows if r["instrument"] == name]
    out = []
    for i, r in enumerate(rows):
        try:
            out.append(float(r[column]))
        except (TypeError, ValueError):
            raise loaded.error(at, f"{path}, data row {i + 1}: '{r[column]}' is not a number") from None
    return np.asarray(out)
