"""dask's error blocks of failed tasks into the run's log file, not onto the terminal.

A task that raises makes its worker log ``Compute Failed`` with the task, the
exception and a traceback at ERROR on the worker's stderr, once per try: the
terminal of a run that then reports the failure in one line would first show
several such blocks.  :class:`TaskErrorsToLog`, registered on every worker,
drops those records from the worker's own handlers and sends their text to the
client as an event; :func:`task_errors_to_log` turns each event into a DEBUG
message of this module's logger, which the run's log file
(``buildingparser.log``, every message DEBUG included) keeps and the terminal
shows only with ``-v``.
"""
from __future__ import annotations

import logging
from typing import Any

from distributed.diagnostics.plugin import WorkerPlugin

logger = logging.getLogger(__name__)

TOPIC = "buildingparser-task-error"


class _ToEvent(logging.Filter):
    """Drops a ``Compute Failed`` record after sending its text to the client."""

    def __init__(self, worker: Any):
        super().__init__()
        self.worker = worker

    def filter(self, record: logging.LogRecord) -> bool:
        text = record.getMessage()
        if not text.startswith("Compute Failed"):
            return True
        try:
            self.worker.log_event(TOPIC, {"worker": str(self.worker.address), "text": text})
        except Exception:  # noqa: BLE001 - never lose a task over its error report
            return True
        return False


class TaskErrorsToLog(WorkerPlugin):
    """On every worker: ``Compute Failed`` blocks go to the client as events instead of to stderr."""

    name = "buildingparser-task-errors-to-log"

    def setup(self, worker) -> None:
        log = logging.getLogger("distributed.worker")
        if not any(isinstance(f, _ToEvent) for f in log.filters):
            log.addFilter(_ToEvent(worker))


def _to_log(event: Any) -> None:
    msg = event[1] if isinstance(event, tuple) and len(event) == 2 else event
    if isinstance(msg, dict):
        logger.debug("task failed on %s: %s", msg.get("worker"), msg.get("text"))
    else:
        logger.debug("task failed: %s", msg)


def task_errors_to_log(client) -> None:
    """Register :class:`TaskErrorsToLog` on the client's workers and log their events here (DEBUG)."""
    if client is None:
        return
    client.register_plugin(TaskErrorsToLog())
    client.subscribe_topic(TOPIC, _to_log)
