"""What the rival rule of `geoback diagnose` costs and buys, read from the accuracy benchmark's CSVs.

A cause is *named* only when no refit of another family comes within ``claims.RIVAL_AIC`` (10) of it
(claims check 3). A looser rule names more true causes on the full library and more wrong ones when
the library lacks the truth (``diagnosis_accuracy.py --leave-out``). This script replays the rule at
other thresholds on the rows of those runs, for the concealed cases with effect size > 3:

  named at threshold t   a row graded 'named', or graded 'explained' with the rival check as its only
                         failed check and its first accepted cause ahead of every refit of another family
                         in round 1 by at least t (plain AIC from the CSV's 'round1' column);

printed per threshold: named right / cases (full-library CSVs) and named / cases, every one a confident
wrong cause (leave-out CSVs). An approximation, said so in the output: the rule itself divides the
difference by the overdispersion the accepted refit leaves where its chi^2 test fails, weighs rivals
from later rounds as well, and dismisses rivals that fail their own claim checks; none of that is in the
CSV. The figures show the direction and rough size of the trade, not what a rerun would give.

    python benchmarks/rival_tradeoff.py --full FULL.csv [...] --leave-out LEAVE_OUT.csv [...]
        [--thresholds 10 8 6 4 2 0]
"""
from __future__ import annotations

import argparse
import csv
import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

from geoback.diagnosis.results import family_of  # noqa: E402

REFIT = re.compile(r"(.+?):dJ=([-\d.e+]+):AIC=([-\d.e+]+)(:NC)?$")


def kind_of(hypothesis: str) -> str:
    """'layer-boundary[clay@12.3]' -> 'layer-boundary'."""
    return hypothesis.split("[", 1)[0]


def lead(row: dict) -> float | None:
    """AIC of round 1's best refit of another family minus that of the first accepted cause (None: not refitted)."""
    first = row["accepted"].split(" + ")[0].strip()
    aic = {}
    for token in row["round1"].split():
        m = REFIT.match(token)
        if m and not m.group(4) and float(m.group(2)) > 0:  # converged and better than the model it extends
            aic[m.group(1)] = float(m.group(3))
    if first not in aic:
        return None
    others = [a for h, a in aic.items() if family_of(kind_of(h)) != family_of(kind_of(first))]
    return min(others) - aic[first] if others else float("inf")


def failed_checks(text: str) -> list[str]:
    """The names of the failed claim checks in the CSV's 'failed_checks' ('rivals(a b) adequacy' -> ['rivals',
    'adequacy']: a check's parenthesised detail, the rivals' keys, may hold spaces)."""
    return re.sub(r"\([^()]*\)", "", text).split()


def only_rivals(row: dict) -> bool:
    """Explained only because a rival of another family ties it: the rival check its one failed check."""
    failed = failed_checks(row["failed_checks"])
    return row["grade"] == "explained" and bool(failed) and set(failed) == {"rivals"}


def named_at(row: dict, threshold: float) -> bool:
    if row["grade"] == "named":
        return True
    if not only_rivals(row):
        return False
    m = lead(row)
    return m is not None and m >= threshold


NEEDED = ("kind", "effect_size", "grade", "failed_checks", "accepted", "round1", "correct")


def refuse(message: str) -> None:
    """A file this script cannot read as meant: said on stderr, exit status 2."""
    print(message, file=sys.stderr)
    raise SystemExit(2)


def concealed(paths: list[Path]) -> list[dict]:
    rows = []
    for path in paths:
        if not path.is_file():
            refuse(f"{path}: no such file (expected a CSV of benchmarks/diagnosis_accuracy.py --out)")
        with open(path, newline="") as fh:
            reader = csv.DictReader(fh)
            missing = [c for c in NEEDED if c not in (reader.fieldnames or [])]
            if missing:
                refuse(f"{path}: line 1: expected the columns of benchmarks/diagnosis_accuracy.py's CSV, "
                       f"found none named {', '.join(missing)}")
            for r in reader:
                if r["kind"].startswith("null") or r["effect_size"] in ("", "nan"):
                    continue
                if float(r["effect_size"]) > 3:
                    rows.append(r)
    return rows


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", type=Path, nargs="*", default=[], help="CSVs of the full library")
    ap.add_argument("--leave-out", type=Path, nargs="*", default=[], help="CSVs of --leave-out runs")
    ap.add_argument("--thresholds", type=float, nargs="+", default=[10, 8, 6, 4, 2, 0])
    a = ap.parse_args(argv)
    full, out = concealed(a.full), concealed(a.leave_out)
    print("Rival rule replayed at other thresholds (plain AIC of round 1's refits: an approximation, see the docstring)")
    print(f"{'threshold [AIC]':>16}  {'named right, full library':>28}  {'confident wrong, leave-out':>28}")
    for t in a.thresholds:
        right = sum(named_at(r, t) and r["correct"] == "True" for r in full)
        wrong = sum(named_at(r, t) for r in out)
        f = f"{right}/{len(full)} = {100 * right / len(full):.1f} %" if full else "-"
        w = f"{wrong}/{len(out)} = {100 * wrong / len(out):.1f} %" if out else "-"
        print(f"{t:>16g}  {f:>28}  {w:>28}")
    if full:
        best = sum(r["correct"] == "True" for r in full)
        print(f"ceiling: the right family accepted first (named or explained) in {best}/{len(full)} = "
              f"{100 * best / len(full):.1f} % of the full library's cases")


if __name__ == "__main__":
    main()
