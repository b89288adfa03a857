"""Stage records: what each stage of a run did, kept in the store so a rerun can skip finished work.

Each stage of :mod:`engine.pipeline.run` has a *fingerprint*: a hash of its name,
its settings and the fingerprints of the stages it reads from.  When a stage
finishes, its record (fingerprint, status, seconds, per-item outcomes, small
outputs) is written to the store document ``meta/stages``.  A rerun skips a
stage whose record is ``ok`` with the same fingerprint (its results are in the
store already); ``--force`` ignores the records.  A stage some of whose tiles
or spaces kept failing is recorded as ``failed`` with those items and errors,
so it is redone on the next run and never mistaken for finished.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

DOC = "stages"


def fingerprint(name: str, settings: Any, *upstream: str) -> str:
    """A stable hash of a stage's name, settings (JSON-able) and upstream fingerprints."""
    blob = json.dumps({"stage": name, "settings": settings, "upstream": list(upstream)}, sort_keys=True,
                      default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


@dataclass
class StageRecord:
    name: str
    fingerprint: str
    status: str  # "ok" or "failed"
    seconds: float = 0.0
    failed: dict[str, str] = field(default_factory=dict)  # item key -> error
    outputs: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {"fingerprint": self.fingerprint, "status": self.status, "seconds": round(self.seconds, 3),
                "failed": self.failed, "outputs": self.outputs}

    @classmethod
    def from_json(cls, name: str, d: dict[str, Any]) -> StageRecord:
        return cls(name, d.get("fingerprint", ""), d.get("status", "failed"), d.get("seconds", 0.0),
                   dict(d.get("failed", {})), dict(d.get("outputs", {})))


class StageLog:
    """The stage records of one store (read and written by the driver only)."""

    def __init__(self, store):
        self.store = store

    def records(self) -> dict[str, StageRecord]:
        doc = self.store.doc(DOC) or {}
        return {k: StageRecord.from_json(k, v) for k, v in doc.items()}

    def get(self, name: str) -> StageRecord | None:
        return self.records().get(name)

    def is_done(self, name: str, fp: str) -> bool:
        """True when the stage finished without failures for exactly these inputs."""
        rec = self.get(name)
        return rec is not None and rec.status == "ok" and rec.fingerprint == fp

    def write(self, record: StageRecord) -> None:
        doc = self.store.doc(DOC) or {}
        doc[record.name] = record.to_json()
        self.store.set_doc(DOC, doc)

    def forget(self, *names: str) -> None:
        """Drop records (a stage being redone invalidates what was built on it)."""
        doc = self.store.doc(DOC) or {}
        for n in names:
            doc.pop(n, None)
        self.store.set_doc(DOC, doc)


@contextlib.contextmanager
def failures_recorded(log: StageLog, name: str, fp: str) -> Iterator[None]:
    """Record a stage as ``failed`` (with each failed tile or space and its error) if its tasks keep failing.

    The exception still propagates: the run stops with a non-zero exit, the
    stages finished before are kept, and the next run redoes this one.
    """
    from tiles.tasks import TaskFailures

    start = time.perf_counter()
    try:
        yield
    except TaskFailures as exc:
        failed = {f"{exc.label}: {key}": f"{type(err).__name__}: {err}" for key, err in exc.failures}
        log.write(StageRecord(name, fp, "failed", time.perf_counter() - start, failed=failed))
        raise


class Timer:
    """Wall seconds of a block: ``with Timer() as t: ...; t.seconds``."""

    def __enter__(self) -> Timer:
        self.start = time.perf_counter()
        self.seconds = 0.0
        return self

    def __exit__(self, *exc) -> None:
        self.seconds = time.perf_counter() - self.start
