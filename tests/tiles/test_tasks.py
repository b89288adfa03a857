"""tiles.tasks.run_tasks: results in item order, failures by key, a window of tasks in flight, progress bars."""
from __future__ import annotations

import io
import logging
import sys
import time

import dask
import pytest

from tiles.tasks import TaskFailures, quiet_progress, run_tasks


def _slow_square(x: int, pause: float) -> int:
    time.sleep(pause)
    return x * x


def _fail_on_three(x: int) -> int:
    if x == 3:
        raise ValueError("three")
    return x


def test_results_come_in_item_order_serially_and_on_the_cluster(client):
    items = [5, 1, 4, 2, 3]
    assert run_tasks(_slow_square, items, extra_args=(0.0,)) == [25, 1, 16, 4, 9]
    assert run_tasks(_slow_square, items, client=client, extra_args=(0.0,)) == [25, 1, 16, 4, 9]


def test_a_failing_task_is_reported_by_its_key(client):
    with pytest.raises(TaskFailures, match="item-3: ValueError: three"):
        run_tasks(_fail_on_three, [1, 2, 3], client=client, keys=["item-1", "item-2", "item-3"])


def test_a_window_of_one_runs_the_tasks_one_at_a_time_and_prepares_each_just_before(client):
    """With ``window=1`` on a 2-worker cluster no two tasks overlap (without it they do), and ``prepare``
    turns each item into its task's argument, once per item, in item order."""
    from distributed import get_task_stream

    def spans(stream):
        return sorted((s["start"], s["stop"]) for t in stream for s in t["startstops"]
                      if s["action"] == "compute")

    def overlaps(intervals) -> int:
        return sum(b[0] < a[1] for a, b in zip(intervals, intervals[1:]))

    with get_task_stream(client) as ts:
        assert run_tasks(_slow_square, [1, 2, 3, 4], client=client, extra_args=(0.3,)) == [1, 4, 9, 16]
    assert overlaps(spans(ts.data)) > 0  # both workers busy at once: the check below can fail
    prepared = []

    def prepare(x: int) -> int:
        prepared.append(x)
        return x + 10

    with get_task_stream(client) as ts:
        got = run_tasks(_slow_square, [1, 2, 3, 4], client=client, extra_args=(0.3,), window=1, prepare=prepare)
    assert got == [121, 144, 169, 196]
    assert prepared == [1, 2, 3, 4]
    intervals = spans(ts.data)
    assert len(intervals) == 4 and overlaps(intervals) == 0


def _double(x: int) -> int:
    return 2 * x


class _Terminal(io.StringIO):
    """A stderr that says it is a terminal."""

    def isatty(self) -> bool:
        return True


def test_progress_is_quiet_when_stderr_is_not_a_terminal(capsys):
    with dask.config.set({"buildingparser.progress": "auto"}):
        assert run_tasks(_double, range(5), label="doubling") == [0, 2, 4, 6, 8]
    assert capsys.readouterr().err == ""
    with dask.config.set({"buildingparser.progress": "always"}):  # asked for: a bar wherever stderr goes
        run_tasks(_double, range(5), label="doubling")
    assert "doubling: 100%" in capsys.readouterr().err


def test_progress_is_a_live_bar_on_a_terminal_that_goes_away_at_the_end(monkeypatch):
    term = _Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    with dask.config.set({"buildingparser.progress": "auto"}):
        run_tasks(_double, range(5), label="doubling")
        drawn = term.getvalue()
        assert drawn.startswith("\rdoubling:") and "/5 [" in drawn  # tqdm's live line, redrawn in place
        assert not drawn.rstrip(" \r").endswith("\n")  # no line left behind: the bar is cleared
        for quiet in (lambda: run_tasks(_double, [1], label="one task"),  # a single task: no bar
                      lambda: _in_quiet_block(lambda: run_tasks(_double, range(5), label="quiet"))):
            before = len(term.getvalue())
            quiet()
            assert term.getvalue()[before:] == ""
    with dask.config.set({"buildingparser.progress": "never"}):
        before = len(term.getvalue())
        run_tasks(_double, range(5), label="never")
        assert term.getvalue()[before:] == ""


def _in_quiet_block(fn):
    with quiet_progress():
        return fn()


def test_each_batch_logs_one_debug_line_at_its_end(caplog):
    with caplog.at_level(logging.DEBUG, logger="tiles.tasks"):
        run_tasks(_double, range(3), label="doubling")
        with pytest.raises(TaskFailures):
            run_tasks(_fail_on_three, [1, 3], label="failing")
    lines = [r.getMessage() for r in caplog.records if r.name == "tiles.tasks"]
    assert len(lines) == 2
    assert lines[0].startswith("doubling: 3/3 tasks in ") and lines[1].startswith("failing: 2/2 tasks in ")


def _refuse_once(item, tally):
    """A task that finds a mistake in its input (and notes every try in ``tally``)."""
    with open(tally, "a") as f:
        f.write(f"{item}\n")
    if item == 3:
        from tiles.errors import UserError

        raise UserError("input.txt", "line 3: 2 columns, expected 3")
    return item


def test_a_user_error_in_a_task_is_not_retried_and_reads_as_its_line(client, tmp_path, capfd):
    import dask

    from tiles.errors import UserError
    from tiles.tasks import run_tasks

    tally = tmp_path / "tries.txt"
    with dask.config.set({"buildingparser.retries": 3}):
        with pytest.raises(UserError) as e:
            run_tasks(_refuse_once, [3], client=client, extra_args=(str(tally),))
    assert e.value.line() == "input.txt: line 3: 2 columns, expected 3"
    assert tally.read_text().splitlines() == ["3"]  # one try, not four
    err = capfd.readouterr().err
    assert "Traceback" not in err and "Compute Failed" not in err
