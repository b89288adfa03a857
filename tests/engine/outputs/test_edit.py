"""Space manipulation on a finished run: merging removes exactly the wall between two rooms; splitting by a line."""
from __future__ import annotations

import json
import os

import laspy
import numpy as np
import pytest
from sklearn.metrics import adjusted_rand_score

from engine.cli import main
from engine.outputs.edit import edit_run, wall_on_seam
from engine.pipeline.run import RunSettings, run
from engine.synth import generate
from tiles.errors import UserError


@pytest.fixture(scope="module")
def finished(tmp_path_factory, structural_model, client):
    d = tmp_path_factory.mktemp("edit")
    laz = d / "b.laz"
    generate(str(laz), seed=21, rooms=4, density=1500, yaw=17.0, format="laz")
    run(str(laz), str(d / "run"), client=client, options=RunSettings(model=structural_model))
    return d / "run"


def _las(folder):
    las = laspy.read(str(folder / "points.laz"))
    return {k: np.asarray(las[k]) for k in ("gt_space", "space_id", "element_id")} | {"x": np.asarray(las.x)}


#: A space parses a room cleanly when at least this share of its points are the room's and of the room's are its.
CLEAN = 0.97


def _clean_touching_pair(folder):
    """Two spaces that touch, each parsing one ground-truth room cleanly (:data:`CLEAN`)."""
    from shapely.geometry import shape

    layer = json.loads((folder / "spaces.geojson").read_text())
    pts = _las(folder)
    pure = {}
    for f in layer["features"]:
        sid = int(f["properties"]["id"])
        mine = pts["gt_space"][pts["space_id"] == sid]
        rooms, counts = np.unique(mine, return_counts=True)
        room = int(rooms[np.argmax(counts)])
        if room >= 0 and counts.max() >= CLEAN * len(mine) and \
                np.mean(pts["space_id"][pts["gt_space"] == room] == sid) >= CLEAN:
            pure[sid] = (room, shape(f["geometry"]))
    for a in sorted(pure):
        for b in sorted(pure):
            if a < b and pure[a][1].buffer(0.2).intersects(pure[b][1].buffer(0.2)):
                return a, b, pure[a][0], pure[b][0]
    pytest.fail("no two cleanly parsed neighbouring spaces in the test building")


def test_merge_removes_exactly_the_wall_between_two_rooms(finished, tmp_path, capsys):
    a, b, room_a, room_b = _clean_touching_pair(finished)
    out = tmp_path / "merged"
    assert main(["edit", str(finished), "--merge", str(a), str(b), "--out", str(out)]) == 0
    record = json.loads((out / "metrics.json").read_text())["edit"]
    before = json.loads((finished / "elements.json").read_text())
    after = json.loads((out / "elements.json").read_text())
    removed = [e for e in before if e["element_id"] in record["removed_elements"]]
    walls = [e for e in removed if e["class"] == "wall"]
    assert walls and {e["class"] for e in removed} <= {"wall", "door", "window"}
    assert {e["space_id"] for e in removed} <= {a, b}
    # every wall of the two rooms that stays is not on their shared boundary, and every removed one is
    from shapely.geometry import shape

    layer = {int(f["properties"]["id"]): shape(f["geometry"]) for f in
             json.loads((finished / "spaces.geojson").read_text())["features"]}
    seam = layer[a].buffer(0.15).intersection(layer[b].buffer(0.15)).boundary
    kept_walls = [e for e in before if e["class"] == "wall" and e["space_id"] in (a, b)
                  and e["element_id"] not in record["removed_elements"]]
    assert all(wall_on_seam(w, seam) for w in walls) and not any(wall_on_seam(w, seam) for w in kept_walls)
    assert {e["space_id"] for e in after} <= {int(f["properties"]["id"]) for f in
                                               json.loads((out / "spaces.geojson").read_text())["features"]}
    assert sum(e["class"] == "floor" and e["space_id"] == min(a, b) for e in after) == 1
    # the points: the removed elements' points are gone, the rest kept in order, the two rooms are one space
    old, new = _las(finished), _las(out)
    gone = np.isin(old["element_id"], record["removed_elements"])
    assert gone.sum() == record["points_removed"] > 0
    np.testing.assert_array_equal(new["x"], old["x"][~gone])
    # against the ground truth with the two rooms merged: those rooms' points are one space (as clean as the parse
    # was), and the building's ARI rises
    rooms = np.isin(new["gt_space"], [room_a, room_b])
    assert np.mean(new["space_id"][rooms] == min(a, b)) >= CLEAN
    was = np.isin(old["gt_space"], [room_a, room_b]) & ~gone  # the same points before the edit
    assert np.mean(new["space_id"][rooms] == min(a, b)) == pytest.approx(np.mean(np.isin(old["space_id"][was], [a, b])))

    def ari(p):
        sel = p["gt_space"] >= 0
        return adjusted_rand_score(np.where(np.isin(p["gt_space"], [room_a, room_b]), room_a, p["gt_space"])[sel],
                                   p["space_id"][sel])

    assert ari(new) > ari(old)
    # the COPC octree says what points.laz says (same records, edited alike), the GeoPackage what the GeoJSON says
    assert (finished / "points.copc.laz").is_file()
    from laspy.copc import CopcReader
    from pyogrio.raw import read

    with CopcReader.open(str(out / "points.copc.laz")) as r:
        octree = r.query().array
    laz = laspy.read(str(out / "points.laz")).points.array
    assert octree.dtype == laz.dtype and len(octree) == len(laz)
    assert np.array_equal(np.sort(octree.view(f"V{laz.dtype.itemsize}")), np.sort(laz.view(f"V{laz.dtype.itemsize}")))
    _, _, _, (ids,) = read(str(out / "spaces.gpkg"), columns=["id"])
    geo = json.loads((out / "spaces.geojson").read_text())["features"]
    assert sorted(ids) == sorted(f["properties"]["id"] for f in geo) and min(a, b) in set(ids)
    assert (out / "report.html").is_file() and (out / "floorplan.svg").is_file()
    # the original run is untouched
    assert json.loads((finished / "elements.json").read_text()) == before


def test_split_by_a_line_gives_two_spaces_on_either_side(finished, tmp_path):
    layer = json.loads((finished / "spaces.geojson").read_text())
    f = max(layer["features"], key=lambda f: f["properties"]["area_m2"])
    sid = int(f["properties"]["id"])
    ring = np.asarray(f["geometry"]["coordinates"][0])[:, :2]
    c = ring.mean(axis=0)
    out = tmp_path / "split"
    record = edit_run(str(finished), str(out), split=sid, line=[c[0], c[1] - 1.0, c[0], c[1] + 1.0])
    new_id = record["new_space"]
    pts = _las(out)
    las = laspy.read(str(out / "points.laz"))
    x = np.asarray(las.x)
    assert np.all(x[pts["space_id"] == new_id] >= c[0] - 1e-6) and np.all(x[pts["space_id"] == sid] <= c[0] + 1e-6)
    ids = [int(g["properties"]["id"]) for g in json.loads((out / "spaces.geojson").read_text())["features"]]
    assert sid in ids and new_id in ids and len(ids) == len(layer["features"]) + 1


def test_refusals_are_one_line_and_nothing_is_written(finished, tmp_path):
    with pytest.raises(UserError, match="overwrite"):
        edit_run(str(finished), str(finished), merge=[0, 1])
    with pytest.raises(UserError, match="no space"):
        edit_run(str(finished), str(tmp_path / "x"), merge=[0, 999])
    with pytest.raises(UserError, match="not a finished run"):
        edit_run(str(tmp_path), str(tmp_path / "y"), merge=[0, 1])
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()
    assert not os.path.exists(str(finished) + ".edit-tmp")
