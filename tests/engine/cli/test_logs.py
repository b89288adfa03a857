"""Messages of the command line: ``logging`` on stderr as ``buildingparser: ...``, -v and -q, the run's log file."""
from __future__ import annotations

import logging
import re
import warnings

import fsspec
import pytest

from engine.cli import main
from engine.cli.logs import LOG_FILE, console_logging, run_log
from tests.engine.handmade import corridor_plan, sample, write_store


@pytest.fixture(scope="module")
def store_url(tmp_path_factory):
    xyz, gt = sample(corridor_plan(2), density=150.0, seed=2)
    return write_store(tmp_path_factory.mktemp("logs") / "b.zarr", xyz, gt).url


def test_verbose_and_quiet_change_what_stderr_shows_not_the_result(store_url, client, tmp_path, capsys):
    base = ["spaces", store_url, "--geojson", str(tmp_path / "s.geojson"), "--scheduler", client.scheduler.address]
    shown = {}
    for flag in (None, "-v", "-q"):
        assert main(base + ([flag] if flag else [])) == 0
        shown[flag] = capsys.readouterr()
        assert "5 spaces" in shown[flag].out  # the command's result, whatever the verbosity
    default, verbose, quiet = shown[None].err, shown["-v"].err, shown["-q"].err
    assert f"buildingparser: dask: {client.scheduler.address}; dashboard:" in default
    assert f"buildingparser: spaces: {tmp_path / 's.geojson'}" in default
    assert all(line.startswith("buildingparser: ") for line in default.splitlines())
    assert not re.search(r"tasks in \d", default)  # DEBUG: only with -v
    assert re.search(r"^buildingparser: .*: \d+/\d+ tasks in \d", verbose, re.M)
    assert f"buildingparser: dask: {client.scheduler.address}" in verbose
    assert quiet == ""


def test_warnings_and_errors_are_one_line_each_and_quiet_keeps_them(capsys):
    log = logging.getLogger("engine.test")
    with console_logging(-1):
        log.info("not shown")
        log.warning("a %s", "warning")
        log.error("an error")
        warnings.warn("from python's warnings", RuntimeWarning, stacklevel=1)
    assert capsys.readouterr().err.splitlines() == ["buildingparser: warning: a warning",
                                                    "buildingparser: error: an error",
                                                    "buildingparser: warning: from python's warnings"]
    log.warning("after the block")  # the handler is gone (pytest's own capture aside)
    assert "buildingparser:" not in capsys.readouterr().err
    with pytest.raises(SystemExit):  # one or the other
        main(["info", "x", "-q", "-v"])
    assert "not allowed with argument" in capsys.readouterr().err


def test_run_log_keeps_debug_lines_with_timestamps_and_the_error_with_its_traceback(tmp_path):
    log = logging.getLogger("engine.pipeline.test")
    with run_log(str(tmp_path / "out")) as path:
        log.debug("a debug line")
        logging.getLogger("tiles.test").info("from tiles")
        logging.getLogger("distributed.test").warning("not ours")
    text = (tmp_path / "out" / LOG_FILE).read_text()
    assert path == str(tmp_path / "out" / LOG_FILE)
    assert re.search(r"^\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3} DEBUG +engine\.pipeline\.test: a debug line$", text, re.M)
    assert "INFO    tiles.test: from tiles" in text and "not ours" not in text
    assert logging.getLogger("engine").level == logging.NOTSET  # restored
    with pytest.raises(ValueError):
        with run_log(str(tmp_path / "out")):
            raise ValueError("simulated failure")
    text = (tmp_path / "out" / LOG_FILE).read_text()
    assert "a debug line" not in text  # one run's log
    assert "ERROR   engine.cli.logs: ValueError: simulated failure" in text and "Traceback" in text


def test_run_log_of_a_url_is_copied_there_and_a_file_as_folder_is_left_to_the_run(tmp_path):
    with run_log("memory://bp-logs/out") as path:
        logging.getLogger("engine.x").info("remote run")
    fs = fsspec.filesystem("memory")
    assert "remote run" in fs.cat("/bp-logs/out/" + LOG_FILE).decode()
    assert path is not None
    blocked = tmp_path / "a-file"
    blocked.write_text("")
    with run_log(str(blocked)) as path:
        assert path is None
