"""The benchmarks' printed table of (quantity, value) rows, optionally also written as CSV."""
from __future__ import annotations

import csv
from pathlib import Path


def print_table(rows: list[tuple], csv_path: Path | None = None) -> dict:
    """Print the rows as an aligned two-column table; with `csv_path`, also write them there. The rows as a dict."""
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k.ljust(width)}  {v}")
    if csv_path:
        csv_path.parent.mkdir(parents=True, exist_ok=True)
        with open(csv_path, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh, lineterminator="\n")
            w.writerow(["quantity", "value"])
            w.writerows(rows)
    return dict(rows)
