"""Paths and URLs: a URL whose protocol's package is missing is one clear line (s3fs is the [s3] extra)."""
from __future__ import annotations

import sys

import pytest

from engine.cli import main
from tiles import paths
from tiles.errors import BuildingParserError, UserError


@pytest.fixture
def no_s3fs(monkeypatch):
    monkeypatch.setitem(sys.modules, "s3fs", None)  # import s3fs now fails, as without the extra


def test_an_s3_url_without_s3fs_names_the_extra(no_s3fs):
    for call in (lambda: paths.normalize("s3://bucket/in.laz"), lambda: paths.filesystem("s3://bucket/in.laz"),
                 lambda: paths.exists("s3://bucket/in.laz")):
        with pytest.raises(UserError) as err:
            call()
        assert isinstance(err.value, BuildingParserError)
        assert err.value.line() == ("s3://bucket/in.laz: s3:// paths need the package s3fs, which is not "
                                    "installed: pip install 'buildingparser[s3]'")
    assert paths.normalize("/tmp/x.laz") == "/tmp/x.laz"  # local paths never ask for it
    assert paths.normalize("memory://x/y/") == "memory://x/y"


def test_the_cli_says_it_in_one_line_with_exit_2(no_s3fs, tmp_path, capsys):
    for argv in (["info", "s3://bucket/store.zarr"], ["export", "s3://bucket/store.zarr", str(tmp_path / "a.laz")]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "pip install 'buildingparser[s3]'" in err[0], err
        assert "Traceback" not in err[0]


def test_s3fs_is_the_s3_extra_and_not_a_dependency():
    import pathlib
    import tomllib

    project = tomllib.loads((pathlib.Path(__file__).resolve().parents[2] / "pyproject.toml").read_text())["project"]
    assert not any(d.startswith("s3fs") for d in project["dependencies"])
    assert any(d.startswith("s3fs") for d in project["optional-dependencies"]["s3"])
    assert any(d.startswith("s3fs") for d in project["optional-dependencies"]["test"])
