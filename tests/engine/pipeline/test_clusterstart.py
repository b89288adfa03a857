"""The cluster started in a thread: waited for by client(), closed on exit even when never asked for."""
from __future__ import annotations

import contextlib
import threading

import pytest

from engine.pipeline.clusterstart import ClusterStart, joined


def _factory(events: list[str], release: threading.Event | None = None, fail: Exception | None = None):
    @contextlib.contextmanager
    def start():
        events.append("start")
        if release is not None:
            release.wait(10)
        if fail is not None:
            raise fail
        events.append("up")
        try:
            yield "client"
        finally:
            events.append("closed")
    return start


def test_client_waits_for_the_start_and_exit_closes_it():
    events: list[str] = []
    release = threading.Event()
    with ClusterStart(_factory(events, release)) as starting:
        events.append("caller works")  # while the start is held
        release.set()
        assert joined(starting) == "client"
        assert events.index("up") > events.index("caller works")
        assert "closed" not in events
    assert events[-1] == "closed"
    assert joined("plain") == "plain"


def test_an_error_of_the_caller_still_closes_a_cluster_that_was_starting():
    events: list[str] = []
    release = threading.Event()
    with pytest.raises(KeyError), ClusterStart(_factory(events, release)):
        release.set()
        raise KeyError("bad input")
    assert events == ["start", "up", "closed"]


def test_the_start_s_own_error_comes_from_client():
    with ClusterStart(_factory([], fail=OSError("no scheduler"))) as starting, pytest.raises(OSError):
        starting.client()
