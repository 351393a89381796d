"""`geoback batch`: identify many cases in parallel and tabulate them in summary.csv.

Which files: a folder means every ``*.yaml`` / ``*.yml`` file in it and in its subfolders,
recursively (hidden files and folders, whose names start with ".", are skipped), so
``geoback batch cases`` runs every shipped case, cases/concealed/ included; a glob pattern
(``*``, ``?``, ``[...]``, ``**`` recursive) means the files it matches (``'cases/*.yaml'``
for the top level only); a file means itself.

Where: a local process pool by default (``workers`` processes, started with the "spawn"
method so that each worker imports numpy afresh after its BLAS/OpenMP thread count has been
limited to 1: several workers must not each start a thread per core), or the Dask
distributed cluster whose scheduler listens at ``scheduler`` (``tcp://host:8786``). A Dask
cluster must see the case files and the output folder under the same paths (a shared file
system); Dask's nanny already starts its workers with OMP/MKL/OPENBLAS_NUM_THREADS=1.

Outputs: each case's results (as `geoback run` writes them) go to ``out/<case name>/``
(``out/<case name>-<file stem>/`` for cases that share a name; the case file's own
``output.dir`` is ignored), and ``out/summary.csv`` holds one row per case file, sorted by
file: case, file, status ("converged", "not converged" or "error"), one column per
parameter name of any case (empty where a case lacks it), reduced_chi2, seconds, message.
A failing case does not stop the others.
"""
from __future__ import annotations

import glob
import os
import re
import time
from pathlib import Path
from typing import Callable, Iterable, Optional

from geoback.errors import GeobackError

THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                    "BLIS_NUM_THREADS", "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")
FIXED_COLUMNS = ("case", "file", "status")
TAIL_COLUMNS = ("warnings", "reduced_chi2", "seconds", "message")  # warnings: the result's caveat codes
CASE_SUFFIXES = (".yaml", ".yml")


def default_workers() -> int:
    return max(1, min(2, os.cpu_count() or 1))


def limit_threads() -> None:
    """Worker initializer: one BLAS/OpenMP/MKL thread per worker process.

    Runs before the worker imports numpy (spawned processes start clean), so the libraries
    read these variables when they load. Keep this module free of heavy imports.
    """
    for name in THREAD_VARIABLES:
        os.environ[name] = "1"


def _has_magic(text: str) -> bool:
    return glob.has_magic(text)


def _walk(folder: Path) -> list[Path]:
    """Files under `folder`, recursively, skipping hidden files and folders."""
    files = []
    for root, dirs, names in os.walk(folder):
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        files += [Path(root) / n for n in names if not n.startswith(".")]
    return files


def collect_cases(targets: Iterable[str | Path]) -> list[Path]:
    """Case files named by folders, glob patterns or files, without duplicates, sorted."""
    found: dict[str, Path] = {}
    for target in targets:
        text = str(target)
        if _has_magic(text):
            matches = [Path(m) for m in glob.glob(text, recursive=True)]
            matches = [m for m in matches if m.is_file()]
            if not matches:
                raise GeobackError(f"no file matches {text}")
        else:
            path = Path(text)
            if path.is_dir():
                matches = [p for p in _walk(path) if p.suffix.lower() in CASE_SUFFIXES]
                if not matches:
                    raise GeobackError(f"{path} holds no case files (*.yaml, *.yml)")
            elif path.is_file():
                matches = [path]
            else:
                raise GeobackError(f"{path}: no such file or folder")
        for m in matches:
            found.setdefault(os.path.normcase(os.path.abspath(m)), m)
    return sorted(found.values(), key=lambda p: str(p))


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    if isinstance(exc, GeobackError):
        return text or type(exc).__name__
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_\-.]+", "_", text).strip("._") or "case"


def case_name_of(path: Path, allow_large: bool = False) -> str:
    """The case's `name` when it loads, else the file stem (the worker reports the error)."""
    try:
        from geoback.case.loading import load_case

        return load_case(path, allow_large=allow_large).case.name
    except Exception:  # noqa: BLE001 - a broken case is reported by its worker
        return _safe(path.stem)


def output_folders(paths: list[Path], names: list[str]) -> list[str]:
    """One folder name per case: its name, or name-stem where names clash; always unique."""
    counts: dict[str, int] = {}
    for n in names:
        counts[n] = counts.get(n, 0) + 1
    folders, used = [], set()
    for p, n in zip(paths, names):
        base = n if counts[n] == 1 else f"{n}-{_safe(p.stem)}"
        folder, k = base, 2
        while folder in used:
            folder, k = f"{base}-{k}", k + 1
        used.add(folder)
        folders.append(folder)
    return folders


def run_one(path: str, out_dir: str, name: str | None = None, in_worker: bool = True,
            allow_large: bool = False) -> dict:
    """Identify one case and write its outputs to out_dir; never raises (picklable, top level).

    In a worker process (`in_worker`) it limits BLAS/OpenMP threads to one; run in the
    calling process it leaves the environment alone. `allow_large`: as `load_case`'s.
    """
    if in_worker:
        limit_threads()
    t0 = time.perf_counter()
    row = {"case": name or _safe(Path(path).stem), "file": path, "status": "error", "parameters": {},
           "std": {}, "units": {}, "warnings": [], "reduced_chi2": None, "seconds": None, "message": "",
           "out": out_dir}
    try:
        try:
            from threadpoolctl import threadpool_limits
        except ImportError:
            threadpool_limits = None
        from geoback.case.loading import load_case
        from geoback.commands.run import run_case

        loaded = load_case(path, allow_large=allow_large)
        row["case"] = loaded.case.name
        if threadpool_limits is not None and in_worker:
            with threadpool_limits(limits=1):
                res = run_case(loaded, Path(out_dir))
        else:
            res = run_case(loaded, Path(out_dir))
        fit = res.fit
        row["status"] = fit.status
        row["parameters"] = {n: float(v) for n, v in zip(res.parameters.names, fit.p)}
        row["std"] = {e.name: float(e.std) for e in res.estimates}
        row["units"] = dict(zip(res.parameters.names, res.parameters.units))
        row["warnings"] = sorted({c.code for c in res.caveats})
        row["reduced_chi2"] = float(res.reliability.reduced_chi2)
        if fit.status != "converged":
            row["message"] = fit.reason
    except Exception as exc:  # noqa: BLE001 - one failing case must not stop the batch
        row["status"], row["message"] = "error", _one_line(exc)
    row["seconds"] = round(time.perf_counter() - t0, 3)
    return row


def _error_row(path: str, name: str, out_dir: str, exc: BaseException) -> dict:
    return {"case": name, "file": path, "status": "error", "parameters": {}, "std": {}, "units": {}, "warnings": [],
            "reduced_chi2": None, "seconds": None, "message": _one_line(exc), "out": out_dir}


def _run_pool(jobs: list[tuple], workers: int, report) -> list[dict]:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    rows = []
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=limit_threads) as pool:
        futures = {pool.submit(run_one, *job[:3], True, job[3]): job for job in jobs}
        for fut in as_completed(futures):
            path, out_dir, name, _ = futures[fut]
            try:
                row = fut.result()
            except Exception as exc:  # noqa: BLE001 - e.g. a worker killed by the OS
                row = _error_row(path, name, out_dir, exc)
            rows.append(row)
            report(row)
    return rows


def _run_dask(jobs: list[tuple], scheduler: str, report) -> list[dict]:
    try:
        from dask.distributed import Client, as_completed
    except ImportError:
        raise GeobackError("--scheduler needs Dask: pip install 'geoback[dask]'") from None
    try:
        client = Client(scheduler, timeout="20s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise GeobackError(f"cannot reach the Dask scheduler at {scheduler}: {_one_line(exc)}") from None
    rows = []
    try:
        # pure=False: a fresh random key per task, so two batches sharing a cluster never merge
        futures = {client.submit(run_one, *job[:3], True, job[3], pure=False): job for job in jobs}
        for fut in as_completed(list(futures)):
            path, out_dir, name, _ = futures[fut]
            try:
                row = fut.result()
            except Exception as exc:  # noqa: BLE001 - e.g. KilledWorker
                row = _error_row(path, name, out_dir, exc)
            rows.append(row)
            report(row)
    finally:
        client.close()
    return rows


def summary_table(rows: list[dict]) -> tuple[list[str], list[list]]:
    """Header and rows of summary.csv: for every parameter (the union over the cases, in order of
    appearance) its estimate, its linearised std ('std NAME') and its unit ('unit NAME'); then the
    result's warning codes (space separated), chi^2/dof, seconds and the message."""
    names: list[str] = []
    for r in rows:
        for n in r["parameters"]:
            if n not in names:
                names.append(n)
    header = list(FIXED_COLUMNS) + [c for n in names for c in (n, f"std {n}", f"unit {n}")] + list(TAIL_COLUMNS)
    table = [[r["case"], r["file"], r["status"]]
             + [c for n in names for c in (r["parameters"].get(n, ""), r.get("std", {}).get(n, ""),
                                           r.get("units", {}).get(n, "") if n in r["parameters"] else "")]
             + [" ".join(r.get("warnings", [])), r["reduced_chi2"] if r["reduced_chi2"] is not None else "",
                r["seconds"] if r["seconds"] is not None else "", r["message"]] for r in rows]
    return header, table


def run_batch(paths: Iterable[str | Path], out: str | Path, workers: int | None = 2,
              scheduler: Optional[str] = None, progress: Optional[Callable[[dict], None]] = None,
              allow_large: bool = False) -> list[dict]:
    """Run every case named by `paths` (folders, globs, files); write out/summary.csv.
    `allow_large`: mesh cases beyond the default size limit (as `load_case`'s).

    Returns the rows sorted by case file: dicts with case, file, status, parameters
    {name: estimate}, reduced_chi2, seconds, message and out (the case's results folder).
    `progress(row)` is called as each case finishes (in completion order).
    """
    from geoback.outputs import write_csv

    files = collect_cases([paths] if isinstance(paths, (str, Path)) else paths)
    workers = default_workers() if workers is None else workers
    if workers < 1:
        raise GeobackError(f"--workers must be at least 1, not {workers}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    names = [case_name_of(p, allow_large) for p in files]
    folders = output_folders(files, names)
    jobs = [(str(p), str(out / f), n, allow_large) for p, f, n in zip(files, folders, names)]
    report = progress or (lambda row: None)
    if scheduler:
        rows = _run_dask(jobs, scheduler, report)
    elif workers == 1 or len(jobs) == 1:
        rows = []
        for job in jobs:
            rows.append(run_one(*job[:3], in_worker=False, allow_large=job[3]))
            report(rows[-1])
    else:
        rows = _run_pool(jobs, min(workers, len(jobs)), report)
    order = {job[0]: i for i, job in enumerate(jobs)}
    rows.sort(key=lambda r: order[r["file"]])
    header, table = summary_table(rows)
    write_csv(out / "summary.csv", header, table)
    return rows


def failed(rows: list[dict]) -> list[dict]:
    """Rows whose case did not converge or raised an error."""
    return [r for r in rows if r["status"] != "converged"]
