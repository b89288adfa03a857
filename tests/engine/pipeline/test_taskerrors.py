"""dask's error blocks of failed tasks go to the run's log (DEBUG), not to the terminal."""
from __future__ import annotations

import logging
import time

import pytest

from engine.pipeline.taskerrors import task_errors_to_log
from tests.engine.pipeline.logged import logged
from tiles.tasks import TaskFailures, run_tasks


def _boom(i):
    raise ValueError(f"a bug, not the input ({i})")


def test_compute_failed_blocks_are_logged_not_printed(client, capfd):
    task_errors_to_log(client)
    with logged("engine.pipeline.taskerrors", logging.DEBUG) as lines:
        with pytest.raises(TaskFailures, match="a bug, not the input"):
            run_tasks(_boom, [7], client=client, label="boom")
        for _ in range(50):  # the events come asynchronously
            if lines:
                break
            time.sleep(0.1)
    assert lines and all("Compute Failed" in x and "a bug, not the input (7)" in x for x in lines)
    assert "Compute Failed" not in capfd.readouterr().err
