"""A run's provenance: version, commit, model and input checksums, non-default settings, times, cluster."""
from __future__ import annotations

import hashlib
import os
import re

import dask

from engine.pipeline.context import RunSettings
from engine.pipeline.provenance import (
    CHUNK,
    Provenance,
    cluster_identity,
    file_sha256,
    git_commit,
    input_identity,
    model_identity,
    run_choices,
)


def test_file_checksum_is_streamed_and_exact(tmp_path):
    data = os.urandom(2 * CHUNK + 123)  # more than one chunk, a ragged end
    (tmp_path / "a.laz").write_bytes(data)
    assert file_sha256(str(tmp_path / "a.laz")) == (len(data), hashlib.sha256(data).hexdigest())
    assert input_identity(str(tmp_path / "a.laz")) == {"name": "a.laz", "size": len(data),
                                                       "sha256": hashlib.sha256(data).hexdigest()}


def test_a_folder_is_summed_over_its_files_and_a_store_is_not_hashed(tmp_path):
    area = tmp_path / "Area_1"
    (area / "room_1").mkdir(parents=True)
    (area / "room_1" / "room_1.txt").write_text("1 2 3\n")
    (area / "b.txt").write_text("x")
    lines = "".join(f"{rel} {hashlib.sha256((area / rel).read_bytes()).hexdigest()}\n"
                    for rel in ("b.txt", "room_1/room_1.txt"))
    got = input_identity(str(area))
    assert got == {"name": "Area_1", "size": 7, "files": 2, "sha256": hashlib.sha256(lines.encode()).hexdigest()}
    assert input_identity(str(area), is_store=True)["sha256"] is None


def test_a_store_rewritten_while_it_is_sized_is_no_error(tmp_path, monkeypatch):
    """A run writes into a tile store given as its input while the checksum thread lists it: a file listed
    and then rewritten (gone when sized) is left out, not an error (it lost the run its input's identity)."""
    import fsspec.implementations.local as local

    store = tmp_path / "b.zarr"
    (store / "tiles" / "t_0_0").mkdir(parents=True)
    (store / "zarr.json").write_text("{}")
    (store / "tiles" / "t_0_0" / "space_id").write_text("1234")
    real = local.LocalFileSystem.size

    def vanishing(self, path):
        if path.endswith("space_id"):
            raise FileNotFoundError(path)
        return real(self, path)

    monkeypatch.setattr(local.LocalFileSystem, "size", vanishing)
    assert input_identity(str(store), is_store=True) == {"name": "b.zarr", "size": 2, "sha256": None, "files": 1}


def test_model_identity_names_the_shipped_model_and_checksums_its_files():
    from engine.detection.model import default_model_path

    got = model_identity(None)
    assert got["name"] == "default" and got["default"] is True
    npz = default_model_path() + ".npz"
    with open(npz, "rb") as f:
        assert got["sha256"]["default.npz"] == hashlib.sha256(f.read()).hexdigest()
    assert set(got["sha256"]) == {"default.json", "default.npz"}
    assert model_identity(default_model_path() + ".npz")["default"] is False


def test_run_choices_leave_out_defaults_and_storage_options():
    opt = RunSettings(crf=False, tile_size=5.0, storage_options={"key": "secret"})
    assert run_choices(opt) == {"crf": False, "tile_size": 5.0}
    assert run_choices(RunSettings()) == {}


def test_git_commit_of_this_work_tree_and_local_cluster():
    g = git_commit()
    assert g is None or (re.fullmatch(r"[0-9a-f]{40}", g["commit"]) and isinstance(g["dirty"], bool))
    assert cluster_identity(None)["kind"] == "local process"


def test_provenance_records_times_input_and_settings(tmp_path, client):
    (tmp_path / "in.las").write_bytes(b"abc")
    p = Provenance(str(tmp_path / "in.las"))
    with dask.config.set({"buildingparser.tiles.size": 7}):
        got = p.finish(model_path=None, options=RunSettings(update=False), client=client)
    assert got["input"] == {"name": "in.las", "size": 3, "sha256": hashlib.sha256(b"abc").hexdigest()}
    assert got["settings"]["buildingparser"]["tiles.size"] == 7.0 and got["settings"]["run"] == {"update": False}
    assert got["started"] <= got["ended"] and got["started"].endswith("+00:00")
    assert got["cluster"]["kind"] == "dask distributed" and got["cluster"]["workers"] >= 1
    assert got["model"]["name"] == "default"
    missing = Provenance(str(tmp_path / "gone.las")).finish(model_path=None, options=RunSettings(), client=None)
    assert missing["input"] is None  # a checksum that cannot be taken does not fail the run
