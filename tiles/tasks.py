"""Running a batch of independent tasks on the dask cluster, with progress and failure reports.

Every stage of the pipeline maps a function over tiles, parts or spaces.  This
module is the one place that submits such a batch: it shows progress (a
``tqdm`` bar on a terminal or in a notebook, nothing when stderr is a file or
a pipe; :func:`progress_bar`), asks dask to retry failed tasks, and reports
failures by key instead of leaving a silent hole.  Without a client the tasks run one after another in this process
(unit tests, tiny inputs).
"""
from __future__ import annotations

import contextlib
import contextvars
import logging
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from tiles.config import setting
from tiles.errors import BuildingParserError, UserError

logger = logging.getLogger(__name__)


class TaskFailures(BuildingParserError):
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
    """No progress bars from the batches of this thread in the block (another thread's batch shows its own)."""
    token = _QUIET.set(bool(quiet) or _QUIET.get())
    try:
        yield
    finally:
        _QUIET.reset(token)


def progress_bar(label: str, total: int) -> Any | None:
    """A ``tqdm`` bar for a batch of ``total`` tasks, or None when no bar is wanted.

    ``buildingparser.progress``: ``auto`` gives a bar to a batch of more than one task when
    stderr is a terminal or the code runs in a Jupyter notebook (a widget, through
    ``tqdm.auto``, when ipywidgets is installed), ``always`` to every batch wherever stderr
    goes, ``never`` to none.  No bar inside a :func:`quiet_progress` block.
    """
    mode = setting("progress")
    if _QUIET.get() or mode == "never" or (mode == "auto" and total <= 1):
        return None
    from tqdm.auto import tqdm

    notebook = any(c.__module__ == "tqdm.notebook" for c in tqdm.__mro__)
    live = notebook or bool(getattr(sys.stderr, "isatty", lambda: False)())
    if mode == "auto" and not live:
        return None
    # on a terminal the bar goes away when its batch ends (the stage's log line stays); elsewhere it is kept
    return tqdm(total=total, desc=label, unit="task", file=sys.stderr, leave=not live, dynamic_ncols=True)


class Progress:
    """Progress of one batch: a live bar while it runs (:func:`progress_bar`), one DEBUG log line at its end."""

    def __init__(self, label: str, total: int):
        self.label, self.total, self.done = label, total, 0
        self.start = time.perf_counter()
        self.bar = progress_bar(label, total)
        self.closed = False

    def update(self, n: int = 1) -> None:
        """``n`` more tasks done; the bar closes when the last one is."""
        self.done += n
        if self.bar is not None:
            self.bar.update(n)
        if self.done >= self.total:
            self.close()

    def close(self) -> None:
        """Remove the bar and log the batch's count and time (once)."""
        if self.closed:
            return
        self.closed = True
        if self.bar is not None:
            self.bar.close()
        logger.debug("%s: %d/%d tasks in %.1f s", self.label, self.done, self.total, time.perf_counter() - self.start)

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


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
        What the progress bar and failure report call this batch.
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
    results: list[Any] = [None] * len(items)
    failures: list[tuple[Any, BaseException]] = []
    with Progress(label, len(items)) as progress:
        if client is None:
            _run_here(fn, items, keys, extra_args, results, failures, progress)
        else:
            _run_on_cluster(client, fn, items, keys, extra_args, results, failures, progress,
                            resources=resources, window=window, prepare=prepare)
    if failures and raise_failures:
        raise TaskFailures(label, failures)
    return results


def _run_here(fn: Callable[..., Any], items: list[Any], keys: list[Any], extra_args: tuple, results: list[Any],
              failures: list[tuple[Any, BaseException]], progress: Progress) -> None:
    """The batch one task after another in this process; results and failures filled in place."""
    for i, item in enumerate(items):
        try:
            results[i] = fn(item, *extra_args)
        except UserError:
            raise
        except Exception as exc:  # noqa: BLE001 - reported by run_tasks with its key
            failures.append((keys[i], exc))
            results[i] = exc
        progress.update()


@dataclass
class UserErrorResult:
    """What a task that found a mistake in the user's input gives back instead of failing."""

    error: UserError


class ReturnUserErrors:
    """A task function whose :class:`UserError` is its result, not its failure.

    A failed task is retried by dask (``buildingparser.retries``) and each try
    logs an error block with a traceback; a mistake in the input fails the
    same way every time, so it is returned once and raised by the driver.
    """

    def __init__(self, fn: Callable[..., Any]):
        self.fn = fn
        self.__name__ = getattr(fn, "__name__", "task")  # dask names the task's key after its function

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        try:
            return self.fn(*args, **kwargs)
        except UserError as exc:
            return UserErrorResult(exc)


def _run_on_cluster(client, fn: Callable[..., Any], items: list[Any], keys: list[Any], extra_args: tuple,
                    results: list[Any], failures: list[tuple[Any, BaseException]], progress: Progress, *,
                    resources: dict | None, window: int | None, prepare: Callable[[Any], Any] | None) -> None:
    """The batch on the cluster (see :func:`run_tasks`); results and failures filled in place."""
    from distributed import as_completed

    retries = setting("retries")
    fn = ReturnUserErrors(fn)
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
            if isinstance(results[i], UserErrorResult):
                client.cancel(futures)
                raise results[i].error
        fut.release()
        progress.update()
