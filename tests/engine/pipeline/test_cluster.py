"""Where work runs: an existing scheduler (tcp, tls) or an embedded LocalCluster; local paths vs remote workers."""
from __future__ import annotations

import logging
import types

import dask
import pytest

from engine.cli import main
from engine.pipeline import cluster
from tests.engine.pipeline.logged import logged
from tiles.errors import UserError


def test_scheduler_address_precedence(monkeypatch):
    monkeypatch.delenv("DASK_SCHEDULER_ADDRESS", raising=False)
    with dask.config.set({"scheduler-address": None, "buildingparser.scheduler": None}):
        assert cluster.scheduler_address() is None
        monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", "tcp://env:8786")
        assert cluster.scheduler_address() == "tcp://env:8786"
        with dask.config.set({"buildingparser.scheduler": "tcp://config:8786"}):
            assert cluster.scheduler_address() == "tcp://config:8786"
            assert cluster.scheduler_address("tls://flag:8786") == "tls://flag:8786"


def _one_task(client):
    return client.submit(lambda x: x + 1, 41, pure=False).result()


def test_existing_scheduler_by_flag_env_and_config(client, monkeypatch):
    address = client.scheduler.address
    with logged("engine.pipeline.cluster") as lines, cluster.cluster_client(address) as c:
        assert _one_task(c) == 42
        assert not cluster.is_remote(c)
    assert f"dask: {address}; dashboard: http" in "\n".join(lines)
    monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", address)
    with dask.config.set({"scheduler-address": None}), cluster.cluster_client(quiet=True) as c:
        assert c.scheduler.address == address
    monkeypatch.delenv("DASK_SCHEDULER_ADDRESS")
    with dask.config.set({"scheduler-address": None, "buildingparser.scheduler": address}), \
            cluster.cluster_client(quiet=True) as c:
        assert c.scheduler.address == address


def test_unreachable_scheduler_is_a_clear_error():
    with dask.config.set({"buildingparser.connect-timeout": "1s"}):
        with pytest.raises(UserError, match="cannot reach the dask scheduler"):
            with cluster.cluster_client("tcp://127.0.0.1:9"):
                pass


def test_embedded_local_cluster():
    with dask.config.set({"scheduler-address": None, "buildingparser.scheduler": None}), \
            logged("engine.pipeline.cluster") as lines, \
            cluster.cluster_client(n_workers=1, memory_limit="1GiB") as c:
        assert len(c.scheduler_info()["workers"]) == 1
        assert _one_task(c) == 42
    assert "dask: local cluster, 1 workers; dashboard: http" in "\n".join(lines)


def test_tls_scheduler_with_dasks_own_security_settings():
    from distributed import LocalCluster
    from distributed.security import Security

    sec = Security.temporary()
    with LocalCluster(n_workers=1, processes=False, protocol="tls://", host="127.0.0.1", security=sec,
                      dashboard_address=None, silence_logs=logging.ERROR) as lc:
        address = lc.scheduler_address
        assert address.startswith("tls://127.0.0.1:")
        with pytest.raises(UserError, match="needs TLS certificates: set distributed.comm.tls.ca-file"):
            with cluster.cluster_client(address):
                pass
        settings = {"distributed.comm.tls.ca-file": sec.tls_ca_file,
                    "distributed.comm.tls.client.cert": sec.tls_client_cert,
                    "distributed.comm.tls.client.key": sec.tls_client_key,
                    "distributed.comm.require-encryption": True}
        with dask.config.set(settings), logged("engine.pipeline.cluster") as lines, \
                cluster.cluster_client(address) as c:
            assert _one_task(c) == 42
    assert f"dask: {address}" in "\n".join(lines)


def _fake_client(address):
    return types.SimpleNamespace(scheduler=types.SimpleNamespace(address=address))


def test_local_paths_refused_for_a_remote_cluster(tmp_path):
    remote = _fake_client("tcp://203.0.113.7:8786")
    assert cluster.is_remote(remote)
    with pytest.raises(UserError, match="local path cannot be read by the workers of the remote cluster "
                                        "tcp://203.0.113.7:8786"):
        cluster.check_reachable(remote, "s3://bucket/a.laz", str(tmp_path / "store.zarr"))
    cluster.check_reachable(remote, "s3://bucket/a.laz", "gs://bucket/store.zarr")  # URLs are fine
    with dask.config.set({"buildingparser.shared-filesystem": True}):
        cluster.check_reachable(remote, str(tmp_path / "store.zarr"))
    for local in ("tcp://127.0.0.1:8786", "tls://localhost:8786", "inproc://10.0.0.1/1/2"):
        assert not cluster.is_remote(_fake_client(local))
    cluster.check_reachable(_fake_client("tcp://127.0.0.1:8786"), str(tmp_path))
    cluster.check_reachable(None, str(tmp_path))


def test_remote_cluster_refusal_through_the_cli(tmp_path, capsys, monkeypatch):
    import contextlib

    @contextlib.contextmanager
    def fake_cluster_client(*a, **k):
        yield _fake_client("tcp://203.0.113.7:8786")

    monkeypatch.setattr(cluster, "cluster_client", fake_cluster_client)
    src = tmp_path / "a.xyz"
    src.write_text("1 2 3\n")
    assert main(["ingest", str(src), str(tmp_path / "s.zarr")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"buildingparser: error: {src}: a local path cannot be read by the workers of the remote "
                   "cluster tcp://203.0.113.7:8786: use an fsspec URL (s3://, gs://...) or, if the workers share "
                   "this file system, set buildingparser.shared-filesystem: true"]


def test_long_commands_print_progress_and_the_dashboard(client, tmp_path, capsys):
    src = tmp_path / "a.xyz"
    src.write_text("".join(f"{i % 37} {i % 23} {i % 3} 1 2 3\n" for i in range(3000)))
    with dask.config.set({"buildingparser.progress": "always"}):
        assert main(["ingest", str(src), str(tmp_path / "s.zarr"), "--part-points", "500",
                     "--scheduler", client.scheduler.address]) == 0
    err = capsys.readouterr().err
    assert f"dask: {client.scheduler.address}; dashboard: http" in err
    assert "reading parts: " in err and "writing tiles: " in err


def test_workers_keep_freed_memory_for_the_next_task(client):
    # tiles.yaml replaces distributed's MALLOC_TRIM_THRESHOLD_ of 64 KB (fresh pages for every large array)
    import os

    want = ("268435456", "268435456")
    assert (dask.config.get("distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_"),
            dask.config.get("distributed.nanny.pre-spawn-environ.MALLOC_MMAP_THRESHOLD_")) == tuple(map(int, want))
    got = client.run(lambda: (os.environ.get("MALLOC_TRIM_THRESHOLD_"), os.environ.get("MALLOC_MMAP_THRESHOLD_")))
    assert set(got.values()) == {want}


def _pools() -> dict:
    import os

    import numcodecs.blosc
    import zarr

    return {"rayon": os.environ.get("RAYON_NUM_THREADS"), "zarr": zarr.config.get("threading.max_workers"),
            "blosc": numcodecs.blosc.get_nthreads()}


@pytest.mark.parametrize("threads", [1, 2])
def test_library_pools_pinned_to_the_worker_threads(threads, monkeypatch):
    """A worker's LAZ decoder (rayon), Zarr and Blosc pools get the worker's thread count, not one per core."""
    from distributed import Client, LocalCluster

    monkeypatch.setenv("RAYON_NUM_THREADS", "7")  # what the worker would inherit otherwise
    with LocalCluster(n_workers=1, threads_per_worker=threads, processes=True, dashboard_address=None,
                      silence_logs=logging.ERROR) as lc, Client(lc) as c:
        before = next(iter(c.run(_pools).values()))
        assert before["rayon"] == "7"  # inherited until pinned
        cluster.pin_library_threads(c)
        after = next(iter(c.run(_pools).values()))
        assert after == {"rayon": str(threads), "zarr": threads, "blosc": threads}
        with dask.config.set({"buildingparser.library-threads": 0}):
            cluster.pin_library_threads(c)  # 0: left alone (the plugin registered before stays)
        assert next(iter(c.run(_pools).values())) == after


def test_embedded_cluster_and_run_pin_library_pools(tmp_path, monkeypatch):
    """cluster_client pins the pools of its workers; so does pipeline.run on a client it is given."""
    from engine.pipeline import run as pipeline
    with dask.config.set({"scheduler-address": None, "buildingparser.scheduler": None}), \
            cluster.cluster_client(n_workers=1, memory_limit="1GiB", quiet=True) as c:
        assert next(iter(c.run(_pools).values()))["rayon"] == "1"
    seen = []
    monkeypatch.setattr(pipeline, "pin_library_threads", seen.append)
    monkeypatch.setattr(pipeline, "check_reachable", lambda *a: None)  # "a client" has no scheduler to ask
    # (the earlier report is withdrawn only once the input is validated: stop at the first work instead)
    (tmp_path / "in.laz").write_bytes(b"")  # the input must exist: it is checked first
    monkeypatch.setattr(pipeline, "temporary_folder", lambda kind: (_ for _ in ()).throw(RuntimeError("stop")))
    with pytest.raises(RuntimeError, match="stop"):
        pipeline.run(str(tmp_path / "in.laz"), str(tmp_path / "out"), client="a client")
    assert seen == ["a client"]


def test_performance_report_reads_offline(client, tmp_path):
    import re

    path = tmp_path / "dask-report.html"
    with cluster.performance_report(client, str(path)):
        client.submit(sum, [1, 2, 3]).result()
    page = path.read_text()
    assert "Dask Performance Report" in page
    # no script or stylesheet fetched from elsewhere (dask's default: bokeh from cdn.bokeh.org)
    assert not re.search(r"<script[^>]+src=[\"']https?://", page)
    assert not re.search(r"<link[^>]+stylesheet[^>]+href=[\"']https?://", page)
    assert "cdn.bokeh.org" not in page and len(page) > 500_000  # bokeh's own code is in the page
    with cluster.performance_report(None, str(tmp_path / "none.html")):
        pass
    assert not (tmp_path / "none.html").exists()


def test_memory_is_trimmed_here_and_in_every_worker(client):
    import sys

    from engine.pipeline.cluster import malloc_trim, trim_memory

    trim_memory(client)
    trim_memory(None)
    done = client.run(malloc_trim)
    assert len(done) == len(client.scheduler_info()["workers"])
    if sys.platform.startswith("linux"):  # glibc: malloc_trim is there (it says whether it gave memory back)
        assert all(isinstance(v, bool) for v in done.values())
    else:
        assert not any(done.values())
