"""The cluster started in a thread while the run checks and opens its inputs (issue 29 item 5).

Starting a LocalCluster (two worker processes, their imports) takes seconds, and
so does a run's own start (importing the engine, checking the input, reading
its header, claiming the output folder, loading the model).  Neither needs the
other: :class:`ClusterStart` starts the cluster in a thread on entry, and
:meth:`ClusterStart.client` waits for it where the first distributed work needs
it.  On exit, after a user error too, it waits for the start to end and closes
the cluster, so nothing is left running.
"""
from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable
from contextlib import AbstractContextManager
from typing import Any


class ClusterStart:
    """A client whose cluster starts in a thread on ``__enter__``; :meth:`client` waits for it.

    Parameters
    ----------
    factory
        Returns the context manager that yields the client (e.g. ``lambda: cluster_client(...)``);
        it is entered in the start thread and exited on ``__exit__``.
    """

    def __init__(self, factory: Callable[[], AbstractContextManager[Any]]):
        self._factory = factory
        self._stack = contextlib.ExitStack()
        self._client: Any = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._start, name="buildingparser-cluster-start", daemon=True)

    def __enter__(self) -> ClusterStart:
        self._thread.start()
        return self

    def _start(self) -> None:
        try:
            self._client = self._stack.enter_context(self._factory())
        except BaseException as exc:  # noqa: BLE001 - handed to the caller by client()
            self._error = exc

    def client(self) -> Any:
        """The connected client, once the cluster has started; the start's own error if it failed."""
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._client

    def __exit__(self, *exc_info: object) -> None:
        self._thread.join()  # a cluster still starting is closed once it is up: none is left behind
        self._stack.close()


def joined(client: Any) -> Any:
    """The client itself, or the started client of a :class:`ClusterStart` (waiting for it)."""
    return client.client() if isinstance(client, ClusterStart) else client
