"""Shared helpers of the benchmarks: peak-memory sampling, timing, and the JSON + table report."""
from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time
from collections.abc import Callable, Sequence
from contextlib import contextmanager
from typing import Any

import psutil

# Register the buildingparser.* defaults first: a suite's ``with dask.config.set({'buildingparser...'})``
# entered before they exist would delete the whole 'buildingparser' section on exit.
import engine.config  # noqa: F401,E402
import tiles.config  # noqa: F401,E402


class PeakMemory:
    """Samples the resident memory of this process and all its children (dask workers) in a thread.

    ``peak_total`` is the largest sum over the process tree, ``peak_single`` the
    largest single process (what one worker held at most).  The list of child
    processes is looked up again only every ``refresh`` seconds: walking the
    process table costs ~1 ms of CPU, twenty times reading a process's memory,
    and on a 2-core machine the sampler's CPU is taken from the measured run.
    """

    def __init__(self, interval: float = 0.05, refresh: float = 2.0):
        self.interval = interval
        self.refresh = refresh
        self.peak_total = 0
        self.peak_single = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._procs: list[psutil.Process] = []
        self._procs_at = -float("inf")

    def sample(self) -> list[int]:
        """Resident bytes of this process and each of its children now (processes that ended are left out)."""
        now = time.perf_counter()
        if now - self._procs_at >= self.refresh:
            me = psutil.Process(os.getpid())
            try:
                self._procs = [me, *me.children(recursive=True)]
            except psutil.Error:
                self._procs = [me]
            self._procs_at = now
        rss = []
        for p in self._procs:
            try:
                rss.append(p.memory_info().rss)
            except psutil.Error:
                self._procs_at = -float("inf")  # a process ended: look the tree up again next time
        return rss

    def _loop(self) -> None:
        while not self._stop.is_set():
            rss = self.sample()
            self.peak_total = max(self.peak_total, sum(rss))
            self.peak_single = max(self.peak_single, max(rss, default=0))
            self._stop.wait(self.interval)

    def __enter__(self) -> PeakMemory:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


@contextmanager
def timed(results: dict[str, float], key: str):
    """Record the wall seconds of a block under ``results[key]``."""
    t0 = time.perf_counter()
    yield
    results[key] = time.perf_counter() - t0


def mib(nbytes: float) -> float:
    return round(nbytes / 2**20, 1)


def format_table(rows: Sequence[dict[str, Any]], columns: Sequence[str] | None = None) -> str:
    """A plain aligned text table."""
    if not rows:
        return "(no rows)"
    columns = list(columns or rows[0].keys())

    def cell(v: Any) -> str:
        if isinstance(v, float):
            return f"{v:.4g}" if abs(v) < 1e5 else f"{v:,.0f}"
        return str(v)

    body = [[cell(r.get(c, "")) for c in columns] for r in rows]
    widths = [max(len(c), *(len(b[i]) for b in body)) for i, c in enumerate(columns)]
    line = "  ".join(c.ljust(w) for c, w in zip(columns, widths))
    out = [line, "  ".join("-" * w for w in widths)]
    out += ["  ".join(v.ljust(w) for v, w in zip(b, widths)) for b in body]
    return "\n".join(out)


def report(result: dict[str, Any], columns: Sequence[str] | None = None, file=sys.stdout) -> None:
    """Print a benchmark result: a readable table of ``result["rows"]``, then the whole result as JSON."""
    print(f"== {result.get('name', 'benchmark')} ==", file=file)
    if result.get("rows"):
        print(format_table(result["rows"], columns), file=file)
    if result.get("summary"):
        print(format_table([result["summary"]]), file=file)
    print(json.dumps(result, default=float), file=file)


def main(run: Callable[..., dict[str, Any]], description: str, columns: Sequence[str] | None = None) -> None:
    """The ``__main__`` of a benchmark module: ``--quick`` for tiny inputs, ``--json FILE`` to save."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--quick", action="store_true", help="tiny inputs (CI smoke run)")
    parser.add_argument("--json", metavar="FILE", help="also write the result as JSON to FILE")
    args = parser.parse_args()
    result = run(quick=args.quick)
    report(result, columns)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=2, default=float)
