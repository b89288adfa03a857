"""Running a batch of independent tasks on the dask cluster, with progress and failure reports.

Every stage of the pipeline maps a function over tiles, parts or spaces.  This
module is the one place that submits such a batch: it shows progress, asks
dask to retry failed tasks, and reports failures by key instead of leaving a
silent hole.  Without a client the tasks run one after another in this process
(unit tests, tiny inputs).
"""
from __future__ import annotations

import contextlib
import contextvars
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import dask

from tiles.errors import UserError


class TaskFailures(Exception):
    """Some tasks of a batch kept failing after their retries."""

    def __init__(self, label: str, failures: list[tuple[Any, BaseException]]):
        self.label = label
        self.failures = failures
        shown = "; ".join(f"{k}: {type(e).__name__}: {e}" for k, e in failures[:5])
        more = f" (and {len(failures) - 5} more)" if len(failures) > 5 else ""
        super().__init__(f"{label}: {len(failures)} task(s) failed: {shown}{more}")


_QUIET = contextvars.ContextVar("buildingparser_quiet_progress", default=False)


@contextlib.contextmanager
def quiet_progress(quiet: bool = True) -> Iterator[None]:
    """No progress lines from the batches of this thread in the block (another thread's batch shows its own)."""
    token = _QUIET.set(bool(quiet) or _QUIET.get())
    try:
        yield
    finally:
        _QUIET.reset(token)


class Progress:
    """Progress of a batch on stderr: a live line on a terminal, a few lines otherwise."""

    def __init__(self, label: str, total: int):
        mode = dask.config.get("buildingparser.progress", "auto")
        self.enabled = not _QUIET.get() and (mode == "always" or (mode == "auto" and total > 1))
        self.tty = sys.stderr.isatty()
        self.label, self.total, self.done = label, total, 0
        self.start = time.perf_counter()
        self._last_pct = -1

    def update(self, n: int = 1) -> None:
        self.done += n
        if not self.enabled:
            return
        pct = int(100 * self.done / max(self.total, 1))
        if self.tty:
            bar = "#" * (pct // 4)
            sys.stderr.write(f"\r{self.label:<28} [{bar:<25}] {self.done}/{self.total}")
            if self.done >= self.total:
                sys.stderr.write(f"  {time.perf_counter() - self.start:.1f}s\n")
            sys.stderr.flush()
        elif pct // 25 > self._last_pct // 25 or self.done >= self.total:
            self._last_pct = pct
            sys.stderr.write(f"{self.label}: {self.done}/{self.total} tasks ({pct}%)"
                             f" {time.perf_counter() - self.start:.1f}s\n")
            sys.stderr.flush()


def run_tasks(fn: Callable[..., Any], items: Sequence[Any], *, client=None, label: str = "tasks",
              keys: Sequence[Any] | None = None, extra_args: tuple = (), raise_failures: bool = True,
              resources: dict | None = None, window: int | None = None,
              prepare: Callable[[Any], Any] | None = None) -> list[Any]:
    """Run ``fn(item, *extra_args)`` for every item; results in item order.

    Parameters
    ----------
    fn, items
        The task function and its first argument per task.
    client
        A ``distributed.Client``; ``None`` runs the tasks serially here.
    label
        What the progress line and failure report call this batch.
    keys
        A readable key per item (tile name, space id) for failure reports.
    raise_failures
        If False, failed tasks give their exception as their result instead of raising.
    window
        At most this many tasks submitted at a time, the next one when one ends
        (in item order): bounds what the batch holds in worker memory when each
        task holds a lot (None: all at once).
    prepare
        With a client: called on the driver with an item just before its task is submitted; its
        result is the task's argument (e.g. futures of the inputs it needs, made
        only when the task is about to run).

    A :class:`tiles.errors.UserError` raised by a task is re-raised as it is (the
    first one), so a bad input found on a worker still reads as one clear line.
    """
    items = list(items)
    keys = list(keys) if keys is not None else list(range(len(items)))
    progress = Progress(label, len(items))
    results: list[Any] = [None] * len(items)
    failures: list[tuple[Any, BaseException]] = []
    if client is None:
        for i, item in enumerate(items):
            try:
                results[i] = fn(item, *extra_args)
            except UserError:
                raise
            except Exception as exc:  # noqa: BLE001 - reported below with its key
                failures.append((keys[i], exc))
                results[i] = exc
            progress.update()
    else:
        from distributed import as_completed

        retries = int(dask.config.get("buildingparser.retries", 2))
        if window is None and prepare is None:
            futures = client.map(fn, items, *[[a] * len(items) for a in extra_args], retries=retries,
                                 pure=False, resources=resources)
            pending = iter(())
        else:
            def submit(i: int):
                arg = prepare(items[i]) if prepare is not None else items[i]
                return client.submit(fn, arg, *extra_args, retries=retries, pure=False, resources=resources)

            first = len(items) if window is None else max(1, int(window))
            futures = [submit(i) for i in range(min(first, len(items)))]
            pending = iter(range(len(futures), len(items)))
        index = {f.key: i for i, f in enumerate(futures)}
        running = as_completed(futures)
        for fut in running:
            nxt = next(pending, None)
            if nxt is not None:
                futures.append(submit(nxt))
                index[futures[-1].key] = nxt
                running.add(futures[-1])
            i = index[fut.key]
            if fut.status == "error":
                exc = fut.exception()
                if isinstance(exc, UserError):
                    client.cancel(futures)
                    raise exc
                failures.append((keys[i], exc))
                results[i] = exc
            else:
                results[i] = fut.result()
            fut.release()
            progress.update()
    if failures and raise_failures:
        raise TaskFailures(label, failures)
    return results
