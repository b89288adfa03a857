"""What a run reads is checked before any cluster starts or folder is made."""
from __future__ import annotations

import time

import pytest

from engine.pipeline.context import RunSettings, check_run_inputs
from engine.pipeline.run import run
from tiles.errors import UserError


def test_missing_or_unknown_inputs_and_models_are_refused_at_once(tmp_path):
    t0 = time.perf_counter()
    with pytest.raises(UserError, match="no such file or folder"):
        check_run_inputs(str(tmp_path / "nope.laz"), RunSettings())
    (tmp_path / "scan.obj").write_bytes(b"v 0 0 0\n")
    with pytest.raises(UserError, match="unknown extension '.obj'"):
        check_run_inputs(str(tmp_path / "scan.obj"), RunSettings())
    (tmp_path / "scan.laz").write_bytes(b"")
    check_run_inputs(str(tmp_path / "scan.laz"), RunSettings())  # exists, known: the reader looks inside later
    (tmp_path / "m.npz").write_bytes(b"")
    with pytest.raises(UserError, match=r"m\.json: no such model file"):
        check_run_inputs(str(tmp_path / "scan.laz"), RunSettings(model=str(tmp_path / "m.npz")))
    (tmp_path / "store.zarr").mkdir()
    (tmp_path / "store.zarr" / "zarr.json").write_text("{}")
    check_run_inputs(str(tmp_path / "store.zarr"), RunSettings())  # a tile store
    (tmp_path / "Area_1").mkdir()
    check_run_inputs(str(tmp_path / "Area_1"), RunSettings())  # a folder: the S3DIS reader looks inside
    assert time.perf_counter() - t0 < 0.5


def test_the_api_refuses_a_missing_input_before_making_the_output_folder(tmp_path):
    with pytest.raises(UserError, match="no such file or folder"):
        run(str(tmp_path / "nope.laz"), str(tmp_path / "out"))
    assert not (tmp_path / "out").exists()


class _Docs:
    """The documents of a store, in memory (what the stage records need)."""

    def __init__(self):
        self.docs = {}

    def doc(self, name):
        return self.docs.get(name)

    def set_doc(self, name, doc):
        self.docs[name] = doc


def test_every_stage_gives_what_it_freed_back_to_the_system(monkeypatch, tmp_path):
    """After each stage the driver and the workers trim their heaps (engine.pipeline.cluster.trim_memory)."""
    import engine.pipeline.context as context

    calls = []
    monkeypatch.setattr(context, "trim_memory", lambda client: calls.append(client))
    ctx = context.RunContext("in.laz", str(tmp_path), RunSettings(), "the client", str(tmp_path), _Docs())
    result, _ = ctx.stage("spaces", "fp", lambda: calls.append("work") or 7, load=lambda: None)
    assert result == 7 and calls == ["work", "the client"]
    assert ctx.stage("spaces", "fp", lambda: 8, load=lambda: 7) == (7, None)  # skipped: nothing run, nothing trimmed
    assert calls == ["work", "the client"]
