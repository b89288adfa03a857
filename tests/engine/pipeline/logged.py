"""A test helper: the messages one logger emits in a block (independent of pytest's own log capture, whose
handlers a LocalCluster's ``silence_logs`` turns down while it runs)."""
from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator


@contextlib.contextmanager
def logged(name: str, level: int = logging.INFO) -> Iterator[list[str]]:
    """``with logged("engine.pipeline.run") as lines:``: the messages of that logger (``level`` and above)."""
    lines: list[str] = []

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            lines.append(record.getMessage())

    log, handler = logging.getLogger(name), Keep(level)
    old = log.level
    log.addHandler(handler)
    log.setLevel(level)
    try:
        yield lines
    finally:
        log.removeHandler(handler)
        log.setLevel(old)
