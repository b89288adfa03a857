"""Scratch of killed runs: named so that a later run can tell it is dead, and removed at the next start.

A run killed with SIGKILL leaves what it was writing: a local temporary folder
(``<tmp>/buildingparser-run-*``, ``-log-``, ``-export-``) and, beside its store
and outputs, hidden scratch (``.store.zarr.export-*`` with the packed tiles of
an export, ``.points.laz.tmp-*``, ``.store.zarr.tmp-*``, ``.<output>.tmp``).

* Temporary folders are made by :func:`temporary_folder`, whose name holds the
  process id: :func:`remove_dead_temporary_folders` removes those whose process
  is gone (on this machine, which is what a local temporary folder is on).
* Hidden scratch in an output folder is removed by
  :func:`remove_scratch_of_killed_runs` while the run holds the folder's lock
  (:mod:`engine.pipeline.outfolder`): no other run can be writing it then.
  Only the names buildingparser makes are matched (a hidden name plus an
  8-hex-digit tag, or an output name plus ``.tmp``).
"""
from __future__ import annotations

import logging
import os
import re
import shutil
import tempfile

logger = logging.getLogger(__name__)

_KINDS = ("run", "log", "export")
_TEMPORARY = re.compile(r"^buildingparser-(run|log|export)-(\d+)-")
#: Files published by a copy to ``.<name>.tmp`` then a rename (the run's outputs and its list of them).
_PUBLISHED = ("points.laz", "points.copc.laz", "spaces.geojson", "floorplan.png", "elements.json", "metrics.json",
              "report.html", "dask-report.html", ".buildingparser-outputs.json")
_SCRATCH = re.compile(r"^\..+\.(export|tmp)-[0-9a-f]{8}$|^\.(" + "|".join(map(re.escape, _PUBLISHED)) + r")\.tmp$")


def temporary_folder(kind: str) -> str:
    """A new local temporary folder ``buildingparser-<kind>-<pid>-*`` (``kind``: run, log or export)."""
    if kind not in _KINDS:
        raise ValueError(f"kind {kind!r} not in {_KINDS}")
    return tempfile.mkdtemp(prefix=f"buildingparser-{kind}-{os.getpid()}-")


def process_alive(pid: int) -> bool:
    """True when process ``pid`` runs on this machine (or may: one of another user)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def remove_dead_temporary_folders(root: str | None = None) -> list[str]:
    """Remove the temporary folders of buildingparser processes that are no longer running; returns them."""
    root = root or tempfile.gettempdir()
    removed = []
    try:
        names = os.listdir(root)
    except OSError:
        return removed
    for name in names:
        m = _TEMPORARY.match(name)
        if m and int(m.group(2)) != os.getpid() and not process_alive(int(m.group(2))):
            shutil.rmtree(os.path.join(root, name), ignore_errors=True)
            removed.append(name)
    if removed:
        logger.info("removed %d temporary folder(s) of killed runs from %s", len(removed), root)
    return removed


def remove_scratch_of_killed_runs(folder: str) -> list[str]:
    """Remove buildingparser's hidden scratch from ``folder`` (call only while holding its lock); returns it."""
    removed = []
    try:
        names = os.listdir(folder)
    except OSError:
        return removed
    for name in names:
        if not _SCRATCH.match(name):
            continue
        p = os.path.join(folder, name)
        if os.path.isdir(p) and not os.path.islink(p):
            shutil.rmtree(p, ignore_errors=True)
        else:
            try:
                os.remove(p)
            except OSError:
                continue
        removed.append(name)
    if removed:
        logger.info("%s: removed scratch of killed runs: %s", folder, ", ".join(sorted(removed)))
    return removed
