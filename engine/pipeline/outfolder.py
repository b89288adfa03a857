"""The output folder is the user's: one run at a time, written only where it may write, nothing of theirs lost.

:func:`claim_output_folder` is entered by ``run`` and ``demo`` before any work
(before the log file, the dask cluster or the input is touched):

* the folder is created if missing and must accept a new file, else one line
  (``UserError``, exit status 2);
* a lock file ``.buildingparser.lock`` holds the running process's pid and host
  under an exclusive ``flock``: a second run into the same folder is refused in
  one line naming the holder; a lock left by a killed run (its ``flock`` is
  gone with the process) is taken over with a warning when it was written on
  this host, refused with a way out when written on another host;
* files of the output names (``report.html``, ``elements.json``, ...) that an
  earlier run did not write are the user's: the run refuses to start unless
  ``--force``.  What a run wrote is listed in ``.buildingparser-outputs.json``
  (name, size, modification time); a folder without that list but with a tile
  store ``store.zarr`` is an earlier version's output folder and counts as ours.

URLs (S3 and other fsspec folders) are not locked nor probed: object stores have
no such locks; the run reports their failures as they come.
"""
from __future__ import annotations

import contextlib
import json
import logging
import os
import socket
import time
from collections.abc import Iterable, Iterator
from typing import Any

from engine.outputs.report import OUTPUTS, REPORT
from tiles import paths
from tiles.errors import UserError
from tiles.leftovers import process_alive, remove_dead_temporary_folders, remove_scratch_of_killed_runs

logger = logging.getLogger(__name__)

LOCK_FILE = ".buildingparser.lock"
MANIFEST_FILE = ".buildingparser-outputs.json"
#: The files a run writes into the output folder (besides ``store.zarr``, which the store builder guards itself).
OUTPUT_NAMES = (*OUTPUTS, REPORT, "buildingparser.log")

_held: dict[str, int] = {}  # lock path -> file descriptor of the locks this process holds


@contextlib.contextmanager
def claim_output_folder(out: str, *, force: bool = False) -> Iterator[None]:
    """Check ``out`` is writable, lock it for this run and refuse foreign files of the output names.

    Re-entrant within one process (``run`` calls it inside the command line's claim).

    Raises
    ------
    UserError
        The folder cannot be created or written, another run holds it, or it
        holds files of the output names that no run wrote (without ``force``).
    """
    if not paths.is_local(out):
        yield
        return
    folder = paths.local_path(paths.normalize(out))
    if os.path.join(folder, LOCK_FILE) in _held:  # this process's run holds it and checked it already
        yield
        return
    check_writable(folder)
    with folder_lock(folder):
        foreign = foreign_outputs(folder)
        if foreign and not force:
            raise UserError(folder, f"holds {', '.join(foreign)} not written by buildingparser: "
                                    "pass --force to overwrite, or choose another --out")
        remove_scratch_of_killed_runs(folder)  # no other run can be writing here while we hold the lock
        remove_dead_temporary_folders()
        if foreign:
            logger.warning("%s: %s (not written by buildingparser) will be overwritten, as --force asks",
                           folder, ", ".join(foreign))
        yield


def check_writable(folder: str) -> None:
    """Create ``folder`` if missing and prove a file can be made in it; one-line ``UserError`` otherwise."""
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise UserError(folder, "the output folder is a file")
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as exc:
        raise UserError(folder, f"cannot create the output folder ({exc.strerror or type(exc).__name__})") from None
    probe = os.path.join(folder, f".buildingparser-probe-{os.getpid()}")
    try:
        with open(probe, "w"):
            pass
        os.remove(probe)
    except OSError as exc:
        raise UserError(folder, f"the output folder is not writable ({exc.strerror or type(exc).__name__})") \
            from None


def _holder(fd: int) -> dict[str, Any]:
    os.lseek(fd, 0, os.SEEK_SET)
    raw = os.read(fd, 4096)
    try:
        doc = json.loads(raw.decode("utf-8")) if raw.strip() else {}
    except ValueError:
        doc = {}
    return doc if isinstance(doc, dict) else {}


@contextlib.contextmanager
def folder_lock(folder: str) -> Iterator[None]:
    """Hold ``folder/.buildingparser.lock`` (pid and host inside, an exclusive ``flock`` on it) for the block."""
    import fcntl

    path = os.path.join(folder, LOCK_FILE)
    host, pid = socket.gethostname(), os.getpid()
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            who = _holder(fd)
            os.close(fd)
            raise UserError(folder, f"another run is writing into this folder (pid {who.get('pid', '?')} on "
                                    f"{who.get('host', '?')} since {who.get('started', '?')}): wait for it to end "
                                    "or choose another --out") from None
        try:
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)  # the holder removed the file as we opened it: lock the new one
    old = _holder(fd)
    if old.get("pid") is not None and old.get("host") not in (None, host):
        os.close(fd)
        raise UserError(folder, f"locked by pid {old['pid']} on host {old['host']} (a run there, or one killed "
                                f"there): if no run is writing into this folder, remove {path}")
    if old.get("pid") is not None:
        state = "still running: not a buildingparser run" if process_alive(int(old["pid"])) else "no longer running"
        logger.warning("%s: taking over the lock of a killed run (pid %s, %s)", folder, old["pid"], state)
    os.ftruncate(fd, 0)
    os.lseek(fd, 0, os.SEEK_SET)
    os.write(fd, json.dumps({"pid": pid, "host": host,
                             "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}).encode())
    os.fsync(fd)
    _held[path] = fd
    try:
        yield
    finally:
        del _held[path]
        with contextlib.suppress(OSError):
            os.remove(path)  # removed while still locked: a waiting run re-opens the new file
        os.close(fd)


def _manifest(folder: str) -> dict[str, Any] | None:
    try:
        with open(os.path.join(folder, MANIFEST_FILE), encoding="utf-8") as f:
            doc = json.load(f)
    except FileNotFoundError:
        return None
    except (OSError, ValueError):
        return {}
    return doc if isinstance(doc, dict) else {}


def _stamp(path: str) -> list[int]:
    st = os.stat(path)
    return [int(st.st_size), int(st.st_mtime_ns)]


def foreign_outputs(folder: str) -> list[str]:
    """The files of :data:`OUTPUT_NAMES` in ``folder`` that no buildingparser run wrote (as they are now)."""
    present = [n for n in OUTPUT_NAMES if os.path.isfile(os.path.join(folder, n))]
    written = _manifest(folder)
    if written is None:
        if os.path.exists(os.path.join(folder, "store.zarr", "zarr.json")):
            return []  # an output folder of a version before the list of written files
        return present
    return [n for n in present if written.get(n) != _stamp(os.path.join(folder, n))]


def record_written(out: str, names: Iterable[str]) -> None:
    """Add files just written into the output folder to its list of what buildingparser wrote."""
    if not paths.is_local(out):
        return
    folder = paths.local_path(paths.normalize(out))
    doc = _manifest(folder) or {}
    for n in names:
        p = os.path.join(folder, n)
        if os.path.isfile(p):
            doc[n] = _stamp(p)
    tmp = os.path.join(folder, f".{MANIFEST_FILE}.tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(doc, f, indent=1, sort_keys=True)
    os.replace(tmp, os.path.join(folder, MANIFEST_FILE))
