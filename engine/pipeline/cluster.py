"""Where work runs: an embedded LocalCluster by default, or an existing dask scheduler.

The one place that decides.  ``--scheduler``, then ``buildingparser.scheduler``,
then ``DASK_SCHEDULER_ADDRESS`` (dask's ``scheduler-address``) name an existing
cluster (``tcp://`` or ``tls://``, security from dask's own ``distributed.comm.tls``
settings); with none of them a LocalCluster is started with one single-threaded
worker per core and the machine's memory shared among them.

Either way, the thread pools that libraries start on their own inside a worker
(the LAZ decoder's, Zarr's codec pool, Blosc's) are pinned to the worker's
thread count (:class:`LibraryThreads`), as dask advises: a single-threaded
worker then uses one core, and two workers on two cores do not oversubscribe
them.  :func:`performance_report` writes dask's report of a block with its
scripts inline (readable offline).
"""
from __future__ import annotations

import contextlib
import logging
import os
import socket
import ssl
from collections.abc import Iterator
from urllib.parse import urlparse

import dask
from distributed import Client, LocalCluster
from distributed.diagnostics.plugin import WorkerPlugin

from engine import config
from engine.pipeline.taskerrors import task_errors_to_log
from tiles import paths
from tiles.errors import UserError

logger = logging.getLogger(__name__)

_LOOPBACK = {"localhost", "127.0.0.1", "::1", "", None}


def scheduler_address(scheduler: str | None = None) -> str | None:
    """The address of the existing cluster to use, or None for an embedded one."""
    return (scheduler or config.setting("scheduler") or dask.config.get("scheduler-address", None)
            or os.environ.get("DASK_SCHEDULER_ADDRESS") or None)


@contextlib.contextmanager
def cluster_client(scheduler: str | None = None, *, n_workers: int | None = None,
                   threads_per_worker: int | None = None, memory_limit: str | int | None = None,
                   quiet: bool = False) -> Iterator[Client]:
    """A connected ``distributed.Client`` for the duration of a ``with`` block.

    Parameters
    ----------
    scheduler
        Address of an existing scheduler; None follows the settings above.
    n_workers, threads_per_worker, memory_limit
        Size of the embedded LocalCluster (ignored for an existing cluster).
    quiet
        Do not log the dashboard link.
    """
    address = scheduler_address(scheduler)
    if address:
        security = _security_for(address)
        try:
            client = Client(address, timeout=config.setting("connect-timeout"), security=security)
        except (OSError, TimeoutError, TypeError, ValueError, ssl.SSLError) as exc:
            raise UserError(address, f"cannot reach the dask scheduler ({type(exc).__name__}: {exc})") from None
        cluster = None
    else:
        workers = n_workers or config.setting("n-workers") or max(1, os.cpu_count() or 1)
        cluster = LocalCluster(
            n_workers=int(workers),
            threads_per_worker=int(threads_per_worker or config.setting("threads-per-worker")),
            memory_limit=memory_limit or config.setting("memory-limit"),
            processes=True,
            dashboard_address=config.setting("dashboard-address"),
            silence_logs=logging.ERROR,
        )
        client = Client(cluster)
    try:
        pin_library_threads(client)
        task_errors_to_log(client)  # dask's error blocks into buildingparser.log, not onto the terminal
        if not quiet:
            link = client.dashboard_link if _has_dashboard(client) else "(no dashboard)"
            where = address or f"local cluster, {len(client.scheduler_info()['workers'])} workers"
            logger.info("dask: %s; dashboard: %s", where, link)
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


class LibraryThreads(WorkerPlugin):
    """Pins the thread pools of the libraries the tasks call to the worker's own thread count.

    Without it a single-threaded worker uses more than one core: lazrs decodes
    the chunks of a LAZ part on a rayon pool of one thread per core (ingest on
    one worker ran at 1.2 cores), and Zarr decodes the chunks of an array read
    on a pool of ``cores + 4`` threads.  That hides work from the scheduler:
    one worker looks faster than it is, and two workers on two cores run four
    decoder threads.  dask does the same for the BLAS and OpenMP pools
    (``OMP_NUM_THREADS=1`` etc. in ``distributed.nanny.pre-spawn-environ``).

    ``setup`` runs on every worker (and every worker that joins later) before
    it runs a task of ours: rayon sizes its pool from ``RAYON_NUM_THREADS``
    when the pool is first used, Zarr its executor from
    ``threading.max_workers`` when it first reads.  A worker that has already
    used them keeps its pools (the setting then has no effect).  Blosc is
    pinned too, although numcodecs uses Blosc's threads only from a process's
    main thread, never from a task's.
    """

    name = "buildingparser-library-threads"

    def __init__(self, threads: int | None = None):
        self.threads = threads

    def setup(self, worker) -> None:
        n = int(self.threads or worker.state.nthreads or 1)
        os.environ["RAYON_NUM_THREADS"] = str(n)
        import numcodecs.blosc
        import zarr

        zarr.config.set({"threading.max_workers": n})
        numcodecs.blosc.set_nthreads(n)


def library_threads() -> int | None:
    """``buildingparser.library-threads``: threads of the libraries' own pools per worker (None: the worker's
    thread count; 0: leave the libraries' defaults)."""
    return config.setting("library-threads")


def pin_library_threads(client: Client | None) -> None:
    """Register :class:`LibraryThreads` on the client's workers (unless ``library-threads`` is 0)."""
    n = library_threads()
    if client is None or n == 0:
        return
    client.register_plugin(LibraryThreads(n), name=LibraryThreads.name)


def malloc_trim() -> bool:
    """Give the free memory of this process's heap back to the system (glibc's ``malloc_trim``).

    A stage frees most of what it allocated, but the heap keeps the freed space between live blocks: after the
    spaces stage of the 600 m² building the two workers held 1.5 GB of it, 0.35 GB once trimmed, and the next
    stages' peaks started from there (dask's documented remedy: "Manually trim memory").  False where there is no
    glibc (macOS, Windows): nothing to do.
    """
    import ctypes

    try:
        return bool(ctypes.CDLL("libc.so.6").malloc_trim(0))
    except (OSError, AttributeError):
        return False


def trim_memory(client: Client | None) -> None:
    """:func:`malloc_trim` in every worker of ``client`` and in this process (between stages)."""
    malloc_trim()
    if client is None:
        return
    try:
        client.run(malloc_trim)
    except Exception as exc:  # a worker gone or busy: trimming is only an economy
        logger.debug("could not trim the workers' memory: %s", exc)


def _security_for(address: str):
    """dask's own security settings (``distributed.comm.tls.*``), checked for a ``tls://`` address."""
    from distributed.security import Security

    security = Security()
    if address.startswith("tls://") and not (security.tls_ca_file and security.tls_client_cert):
        raise UserError(address, "a tls:// scheduler needs TLS certificates: set distributed.comm.tls.ca-file, "
                                 "distributed.comm.tls.client.cert and distributed.comm.tls.client.key (dask config "
                                 "file or DASK_DISTRIBUTED__COMM__TLS__CA_FILE=...)")
    return security


def _has_dashboard(client: Client) -> bool:
    try:
        return bool(client.scheduler_info().get("services", {}).get("dashboard"))
    except Exception:  # noqa: BLE001
        return False


def is_remote(client: Client | None) -> bool:
    """True when the client's workers may run on other machines."""
    if client is None:
        return False
    addr = client.scheduler.address if client.scheduler else ""
    parsed = urlparse(addr)
    if parsed.scheme == "inproc":
        return False
    host = parsed.hostname
    return host not in _LOOPBACK and host != socket.gethostname() and host not in _own_addresses()


def _own_addresses() -> set[str]:
    """This machine's IP addresses (every interface) and the address its host name resolves to."""
    out: set[str] = set()
    try:
        out.add(socket.gethostbyname(socket.gethostname()))
    except OSError:
        pass
    try:
        import psutil

        for addrs in psutil.net_if_addrs().values():
            out.update(a.address.split("%")[0] for a in addrs if a.family in (socket.AF_INET, socket.AF_INET6))
    except Exception:  # noqa: BLE001 - best effort
        pass
    return out


def check_reachable(client: Client | None, *locations: str) -> None:
    """Refuse local paths when the workers are elsewhere and share no file system with us."""
    if not is_remote(client) or config.setting("shared-filesystem"):
        return
    for loc in locations:
        if loc and paths.is_local(str(loc)):
            raise UserError(loc, "a local path cannot be read by the workers of the remote cluster "
                                 f"{client.scheduler.address}: use an fsspec URL (s3://, gs://...) or, if the "
                                 "workers share this file system, set buildingparser.shared-filesystem: true")


@contextlib.contextmanager
def performance_report(client, path: str):
    """dask's performance report of the block into ``path`` (when there is a cluster and bokeh).

    Bokeh's scripts are inlined (``mode="inline"``), so the page shows its plots
    offline (dask's default loads them from a CDN).  The report is a by-product:
    if dask cannot write it (no bokeh on the scheduler, a lost connection), the
    run goes on and logs a warning.
    """
    import importlib.util

    if client is None or importlib.util.find_spec("bokeh") is None:
        yield
        return
    from distributed import performance_report as pr

    report = pr(filename=path, mode="inline")
    report.__enter__()
    try:
        yield
    finally:
        try:
            report.__exit__(None, None, None)
        except Exception as exc:  # noqa: BLE001 - never lose a run for its performance report
            logger.warning("dask performance report not written: %s: %s", type(exc).__name__, exc)
