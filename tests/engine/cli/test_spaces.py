"""``buildingparser spaces``: parses a store, prints the spaces and ARI, writes the floor plan and GeoJSON."""
from __future__ import annotations

import json

from engine.cli import main
from tests.engine.handmade import corridor_plan, sample, write_store


def test_spaces_command_writes_labels_png_and_geojson(tmp_path, capsys):
    xyz, gt = sample(corridor_plan(2), density=150.0, seed=2)
    store = write_store(tmp_path / "b.zarr", xyz, gt)
    png, gj = tmp_path / "plan.png", tmp_path / "spaces.geojson"
    gpkg = tmp_path / "spaces.gpkg"
    code = main(["spaces", store.url, "--png", str(png), "--geojson", str(gj), "--gpkg", str(gpkg), "--workers", "1"])
    out = capsys.readouterr().out
    assert code == 0
    assert "5 spaces" in out and "ARI final" in out
    assert png.stat().st_size > 1000
    assert len(json.loads(gj.read_text())["features"]) == 5
    import pyogrio

    assert pyogrio.read_info(str(gpkg))["features"] == 5
    assert "space_id" in store.refresh().meta.names()


def test_spaces_command_reports_a_missing_store(tmp_path, capsys):
    code = main(["spaces", str(tmp_path / "nope.zarr"), "--workers", "1"])
    assert code == 2
    assert "no such tile store" in capsys.readouterr().err
