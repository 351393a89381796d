"""Each command's result files replaced as a whole set (single files: ``outputs.py``).

``result_set(folder, kind)`` is what every writer of results uses::

    with result_set(out, "run") as staging:      # staging: a hidden sibling folder of `out`
        write_csv(staging / "parameters.csv", ...)
        write_atomic(staging / "report.md", ...)
    # here `out` holds the complete new set; an exception or Ctrl-C inside the block leaves it as it was

so that whenever the process stops, kill -9 included, `out` holds either the complete previous
set of that kind or the complete new one, never a mix (no new parameters.csv beside an old
report.md). See :func:`result_set` for how, and :func:`check_result_set` to verify a folder.
"""
from __future__ import annotations

import contextlib
import ctypes
import errno
import hashlib
import json
import os
import shutil
import signal
import socket
import stat
import tempfile
import threading
import time
import uuid
from pathlib import Path
from typing import Iterator

from geoback.errors import GeobackError

MANIFEST = ".geoback-{kind}.json"  # inside a results folder: the files of that kind's set, with checksums
_TAG = ".geoback-"  # staging, complete and retired folders: .<name>.geoback-<host>-<pid>-<token>.new|.ready|.old
_HOST = "".join(c if c.isalnum() or c in "-_" else "_" for c in socket.gethostname())[:40] or "host"
_LOCK = threading.Lock()
_SETS: dict[str, list[str]] = {"open": [], "done": [], "abandoned": []}  # folders, for interrupted_note()


class ResultFolderError(GeobackError):
    """A results folder that cannot be used (a file, not writable, the current folder, ...)."""


def check_out(value: str | os.PathLike | None, option: str = "--out", single_file: bool = False,
              replaced: bool = True) -> Path | None:
    """Refuse, before any work, an output place that cannot take results; return it as a Path.

    `value` as the user typed it (None: not given). Refused: an empty name, an existing file
    where a folder is meant (or a folder where a file is meant, with `single_file`), a place
    that cannot be created or written, and, for a folder, the current folder or one of its
    ancestors or a folder holding subfolders (a results folder is replaced as a whole: its
    other files are carried over, subfolders would not be); `replaced=False` (a folder that
    only receives files and subfolders, as batch's) skips these last two.
    """
    if value is None:
        return None
    text = os.fspath(value)
    if not str(text).strip():
        raise ResultFolderError(f"{option}: expected a {'file' if single_file else 'folder'} name, found an empty string")
    path = Path(text)
    where = f"{option} {text}"
    if single_file:
        if path.is_dir():
            raise ResultFolderError(f"{where}: expected a file name, found an existing folder")
        _check_creatable(path.parent, where)
        return path
    if path.is_symlink() and not path.exists():
        raise ResultFolderError(f"{where}: expected a folder for the results, found a link to nothing")
    if path.exists():
        if not path.is_dir():
            raise ResultFolderError(f"{where}: expected a folder for the results, found an existing file")
        here = Path.cwd().resolve()
        real = path.resolve()
        if not replaced:
            _check_creatable(real, where)
            return path
        if real == here or real in here.parents:
            raise ResultFolderError(f"{where}: expected a folder for the results, found the current folder"
                                    f"{'' if real == here else ' (or one holding it)'}: results replace their "
                                    f"folder as a whole; name a subfolder, e.g. {option} results")
        _check_folder_contents(path, where)
        if not os.access(path, os.R_OK | os.X_OK):
            raise ResultFolderError(f"{where}: expected a folder geoback can read, found one it cannot")
        _check_creatable(path.resolve().parent, where)
        return path
    _check_creatable(path.parent, where)
    return path


def _check_creatable(parent: Path, where: str) -> None:
    """Can folders and files be created in `parent` (made as needed)?"""
    probe = Path(os.path.abspath(parent))
    while not probe.exists():
        if probe.is_symlink():
            raise ResultFolderError(f"{where}: expected a place that can be created, found a broken link {probe}")
        probe = probe.parent
    if not probe.is_dir():
        raise ResultFolderError(f"{where}: expected a folder to write into, found the file {probe} in the way")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise ResultFolderError(f"{where}: expected a place geoback can write, found {probe} not writable")
    try:  # permissions are not the whole story (read-only mounts, ACLs, special file systems): try
        os.rmdir(tempfile.mkdtemp(prefix=".geoback-probe-", dir=probe))
    except OSError as exc:
        raise ResultFolderError(f"{where}: expected a place geoback can write, found {probe} not writable "
                                f"({exc.strerror or exc})") from None


def _check_folder_contents(folder: Path, where: str) -> None:
    try:
        entries = list(os.scandir(folder))
    except OSError as exc:
        raise ResultFolderError(f"{where}: cannot read the folder ({exc.strerror or exc})") from None
    for entry in entries:
        if not entry.is_file(follow_symlinks=False):
            kind = "subfolder" if entry.is_dir(follow_symlinks=False) else "link or special file"
            raise ResultFolderError(f"{where}: expected a results folder (new, or holding only files), found the "
                                    f"{kind} '{entry.name}' in it: results replace their folder as a whole; "
                                    f"name another folder")


@contextlib.contextmanager
def result_set(folder: str | os.PathLike, kind: str, run_id: str | None = None) -> Iterator[Path]:
    """Write one command's set of result files into `folder`, replacing its previous set as a whole.

    Yields a staging folder (hidden sibling ``.<name>.geoback-<host>-<pid>-<token>.new``): write
    every file of the set there, with any writer (write_csv, write_atomic, meshio, savefig...).
    When the block ends normally the files of `folder` that belong to no set of this `kind`
    (other commands' results: `run`, `simulate`, `diagnose` and `mesh` share results/<name>) are
    hard-linked beside the new set, a manifest ``.geoback-<kind>.json`` (run id, file names and
    SHA-256) is added, and the staging folder and `folder` are exchanged in one atomic step
    (Linux renameat2 RENAME_EXCHANGE; elsewhere two renames, with a recovery on the next call
    for a process killed between them). The previous folder is then deleted. When the block
    raises (KeyboardInterrupt included), the staging folder is deleted and `folder` is left
    untouched. Staging and retired folders left by killed processes are removed on the next call.

    `kind` names the set (e.g. "run", "simulate", "diagnose", "mesh"); files of the previous set
    of the same kind that the new set does not write are dropped. `run_id` is recorded in the
    manifest (default: a new random id).
    """
    check_out(folder, "the results folder")  # the command line's checks, for library callers too: never
    folder = Path(folder)                     # the current folder or one holding it, a file, a place not writable
    if not folder.name or folder.name in (".", "..") or folder.is_symlink():
        folder = folder.resolve()  # a linked results folder: its target is replaced, the link kept
    parent = folder.parent
    parent.mkdir(parents=True, exist_ok=True)
    _recover(folder)
    if folder.is_dir():
        _check_folder_contents(folder, str(folder))
    elif folder.exists():
        raise ResultFolderError(f"{folder}: expected a folder for the results, found an existing file")
    token = uuid.uuid4().hex[:8]
    staging = parent / f".{folder.name}{_TAG}{_HOST}-{os.getpid()}-{token}.new"
    staging.mkdir()
    key = str(folder)
    with _LOCK:
        _SETS["open"].append(key)
    ready = staging.with_suffix(".ready")  # the complete set, named so before it is swapped in
    retired = staging.with_suffix(".old")
    try:
        yield staging
        _carry_over(folder, staging, kind, run_id or uuid.uuid4().hex[:16])
        with _deferred_interrupt():
            os.rename(staging, ready)
            _swap(folder, ready)
            with contextlib.suppress(OSError):  # housekeeping: `ready` now holds the previous folder
                os.rename(ready, retired)
            with _LOCK:
                _SETS["open"].remove(key)
                _SETS["done"].append(key)
    except BaseException:
        with _LOCK:
            if key in _SETS["open"]:
                _SETS["open"].remove(key)
                _SETS["abandoned"].append(key)
        raise
    finally:
        for leftover in (staging, ready, retired):
            _remove_tree(leftover)


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _read_manifest(path: Path) -> dict:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        return data if isinstance(data, dict) and isinstance(data.get("files"), dict) else {}
    except (OSError, ValueError):
        return {}


def _carry_over(folder: Path, staging: Path, kind: str, run_id: str) -> dict:
    """Complete the staging folder: the old folder's files that are not this set's, manifests."""
    new_files = sorted(p.name for p in staging.iterdir() if p.is_file() and not p.name.startswith(".geoback-"))
    own = MANIFEST.format(kind=kind)
    files = {name: _sha256(staging / name) for name in new_files}
    if folder.is_dir():
        previous = _read_manifest(folder / own).get("files", {})
        for entry in os.scandir(folder):
            name = entry.name
            if name in files or name == own or name in previous:
                continue
            if name.startswith(".") and name.endswith(".tmp"):
                continue  # a temporary file of write_atomic killed midway
            if not entry.is_file(follow_symlinks=False):
                continue  # refused by _check_folder_contents; never here in practice
            target = staging / name
            if name.startswith(".geoback-") and name.endswith(".json"):
                other = _read_manifest(Path(entry.path))  # another kind's set: note files this one replaced
                replaced = [n for n in other.get("files", {}) if n in files]
                if replaced:
                    for n in replaced:
                        other["files"].pop(n)
                    other.setdefault("replaced", {}).update({n: kind for n in replaced})
                    target.write_text(json.dumps(other, indent=2) + "\n", encoding="utf-8")
                    continue
            try:
                os.link(entry.path, target)
            except OSError:
                shutil.copy2(entry.path, target)
    manifest = {"kind": kind, "run_id": run_id, "written": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                "files": files}
    (staging / own).write_text(json.dumps(manifest, indent=2) + "\n", encoding="utf-8")
    return manifest


def check_result_set(folder: str | os.PathLike, kind: str) -> list[str]:
    """Problems of the `kind` set in `folder` (empty when its manifest exists and every file it
    lists is present with its recorded checksum)."""
    folder = Path(folder)
    manifest = _read_manifest(folder / MANIFEST.format(kind=kind))
    if not manifest:
        return [f"no readable {MANIFEST.format(kind=kind)} in {folder}"]
    problems = []
    for name, digest in manifest["files"].items():
        path = folder / name
        if not path.is_file():
            problems.append(f"{name}: missing")
        elif _sha256(path) != digest:
            problems.append(f"{name}: not the file of run {manifest.get('run_id')}")
    return problems


# ------------------------------------------------------------------ the swap
def _renameat2():
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    fn.restype = ctypes.c_int
    return fn


_RENAMEAT2 = _renameat2() if os.name == "posix" else None
_AT_FDCWD, _RENAME_EXCHANGE = -100, 2


def _exchange(a: Path, b: Path) -> bool:
    """Atomically exchange two paths; False where the system or file system cannot."""
    if _RENAMEAT2 is None:
        return False
    if _RENAMEAT2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV):
        return False
    raise OSError(err, os.strerror(err), str(b))


def _swap(folder: Path, ready: Path) -> None:
    """Put ready's content at `folder`; afterwards `ready` holds the previous folder (if any)."""
    try:
        os.rename(ready, folder)  # no folder yet: one atomic rename
        ready.mkdir()  # (an empty previous folder, for the caller to remove)
        return
    except OSError as exc:
        if exc.errno not in (errno.EEXIST, errno.ENOTEMPTY, errno.EISDIR, errno.ENOTDIR):
            raise
    if _exchange(ready, folder):
        return
    # two renames: the folder is briefly absent; _recover() finishes the job if killed in between
    retired = ready.with_suffix(".old")
    os.rename(folder, retired)
    os.rename(ready, folder)
    os.rename(retired, ready)


@contextlib.contextmanager
def _deferred_interrupt():
    """Hold Ctrl-C (SIGINT) during the swap, so that the bookkeeping of what was written is exact."""
    blocked = False
    if hasattr(signal, "pthread_sigmask") and threading.current_thread() is threading.main_thread():
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        blocked = True
    try:
        yield
    finally:
        if blocked:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def _leftovers(folder: Path) -> list[tuple[Path, str, bool]]:
    """Staging/retired siblings of `folder`: (path, 'new'|'old', owner certainly gone)."""
    prefix = f".{folder.name}{_TAG}"
    out = []
    try:
        entries = list(os.scandir(folder.parent))
    except OSError:
        return out
    for entry in entries:
        name = entry.name
        if not name.startswith(prefix) or not name.endswith((".new", ".ready", ".old")):
            continue
        host, _, rest = name[len(prefix):].rsplit(".", 1)[0].rpartition("-")[0].rpartition("-")
        try:
            pid = int(rest)
        except ValueError:
            continue
        if host == _HOST and os.name == "posix":
            gone = pid != os.getpid() and not _alive(pid)
        else:  # another machine on a shared file system (or no cheap liveness test): trust age only
            try:
                gone = time.time() - entry.stat(follow_symlinks=False).st_mtime > 86400
            except OSError:
                gone = False
        out.append((Path(entry.path), name.rsplit(".", 1)[1], gone))
    return out


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _recover(folder: Path) -> None:
    """Clean up after processes killed while writing next to `folder`: a missing folder (killed
    between the two renames of the fallback swap) is put back from the complete set (``.ready``)
    or else the retired one (``.old``); everything else left over is removed."""
    leftovers = [(p, k) for p, k, gone in _leftovers(folder) if gone]
    if not leftovers:
        return
    if not folder.exists():
        complete = [p for p, k in leftovers if k == "ready"]
        retired = [p for p, k in leftovers if k == "old"]
        for candidate in complete + retired:
            try:
                os.rename(candidate, folder)
                break
            except OSError:
                continue
    for path, _ in leftovers:
        if path.exists():
            _remove_tree(path)


def _remove_tree(path: Path) -> None:
    def retry(func, p, _exc):
        try:
            os.chmod(p, stat.S_IWRITE | stat.S_IREAD | stat.S_IEXEC)
            func(p)
        except OSError:
            pass

    if path.exists():
        shutil.rmtree(path, onerror=retry)


def interrupted_note() -> str:
    """What a Ctrl-C left behind, in words that are true (for the CLI's message)."""
    with _LOCK:
        unfinished = _SETS["open"] + _SETS["abandoned"]
        done = [f for f in _SETS["done"] if f not in unfinished]
    if unfinished:
        where = ", ".join(dict.fromkeys(unfinished))
        text = f"{where} still holds its previous results (new results are put in place only when complete)"
        if done:
            text += f"; the results in {', '.join(dict.fromkeys(done))} are complete"
        return text
    if done:
        return f"the results in {', '.join(dict.fromkeys(done))} are complete"
    return "no results were written"
