"""Space parsing end to end: labels in every tile, the meta/spaces document, ARI, yaw invariance, outputs."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from engine.metrics.ari import distributed_ari
from engine.outputs.geojson import write_spaces_geojson
from engine.spaces.document import SpaceParse
from engine.spaces.parse import parse_spaces
from tests.engine.handmade import Plan, Room, corridor_plan, sample, transform, write_store


@pytest.fixture(scope="module")
def corridor_points():
    return sample(corridor_plan(4), density=250.0, seed=5)


@pytest.fixture(scope="module")
def corridor(tmp_path_factory, corridor_points, client):
    xyz, gt = corridor_points
    store = write_store(tmp_path_factory.mktemp("b") / "corridor.zarr", transform(xyz, 0.0, (500.0, 300.0, 20.0)),
                        gt, client=client)
    return store, parse_spaces(store, client=client)


def _labels(store, name):
    """A per-point array of the whole store in input order."""
    cols = [store.read(t, [name, "point_index"]) for t in store.tiles]
    values = np.concatenate([c[name] for c in cols])
    return values[np.argsort(np.concatenate([c["point_index"] for c in cols]))]


def test_every_point_gets_a_cell_and_a_space(corridor):
    store, parse = corridor
    store.refresh()
    for name in ("cell_id", "space_id"):
        dim = store.meta.dimension(name)
        assert dim is not None and dim.kind == "result" and dim.dtype == "int32"
        for t in store.tiles:
            a = store.read(t, [name])[name]
            assert a.dtype == np.int32 and len(a) == t.count
    cells, spaces = _labels(store, "cell_id"), _labels(store, "space_id")
    assert len(cells) == store.meta.point_count
    assert cells.min() >= 0 and spaces.min() >= 0  # a closed building: no point is left out
    assert parse.unassigned_points == 0
    # a cell lies in exactly one space, as the document says
    cell_space = {c.id: c.space for c in parse.cells}
    assert np.array_equal(spaces, np.array([cell_space[c] for c in cells]))


def test_corridor_building_is_parsed_into_its_rooms(corridor):
    store, parse = corridor
    assert len(parse.spaces) == 9  # the corridor and 2 x 4 rooms
    assert len(parse.floors) == 1
    assert distributed_ari(store) >= 0.95
    assert distributed_ari(store, pred="cell_id") <= distributed_ari(store) + 1e-9


def test_the_document_describes_frame_cells_dividers_and_spaces(corridor):
    store, parse = corridor
    doc = store.doc("spaces")
    assert {"frame", "grid", "floors", "cells", "dividers", "spaces"} <= set(doc)
    assert SpaceParse.from_doc(doc).to_doc() == doc
    assert abs((math.degrees(doc["frame"]["yaw"]) + 45) % 90 - 45) < 0.1
    assert sum(s["point_count"] for s in doc["spaces"]) == store.meta.point_count
    assert sum(c["point_count"] for c in doc["cells"]) == store.meta.point_count
    walls = [d for d in doc["dividers"] if d["kind"] == "peak-gap-peak" and d["axis"] in "uv"]
    assert walls and all(0.05 <= d["width"] <= 0.5 for d in walls)
    corridor_space = max(parse.spaces, key=lambda s: len(s.neighbours))
    assert len(corridor_space.neighbours) == 8  # every room opens on the corridor
    b = store.meta.bounds
    for s in parse.spaces:
        ring = np.array(s.footprint["coordinates"][0])
        assert b[0] - 0.5 <= ring[:, 0].min() and ring[:, 0].max() <= b[3] + 0.5  # world coordinates
        assert s.area_m2 > 5 and s.tiles and b[2] - 0.01 <= s.z_range[0] < s.z_range[1] <= b[5] + 0.01
        for nb in s.neighbours:
            for f in nb.faces:
                assert f.axis in ("u", "v") and f.extent[1] > f.extent[0] and len(f.segment) == 2
            assert any(f.divider for f in nb.faces)  # neighbours behind a wall (with a door)


def test_a_building_turned_by_30_degrees_gives_the_same_spaces(tmp_path, corridor_points, corridor, client):
    xyz, gt = corridor_points
    store = write_store(tmp_path / "turned.zarr", transform(xyz, 30.0, (500.0, 300.0, 20.0)), gt, client=client)
    parse = parse_spaces(store, client=client)
    assert len(parse.spaces) == len(corridor[1].spaces)
    # the same areas up to a bin or two of each wall (1 cm bins along the turned axes)
    assert sorted(s.area_m2 for s in parse.spaces) == pytest.approx(sorted(s.area_m2 for s in corridor[1].spaces),
                                                                   rel=0.02)
    assert distributed_ari(store, client=client) >= 0.95


def test_two_storeys_and_outliers(tmp_path):
    plan = corridor_plan(2, floors=2)
    xyz, gt = sample(plan, density=150.0, seed=1)
    far = np.array([[60.0, 60.0, 1.0], [60.2, 60.1, 1.2], [-40.0, 3.0, 2.0]])  # stray points beyond the building
    store = write_store(tmp_path / "two.zarr", np.vstack([xyz, far]), np.r_[gt, -1, -1, -1].astype(np.int32))
    parse = parse_spaces(store)
    assert len(parse.floors) == 2
    assert [len([s for s in parse.spaces if s.floor == f]) for f in (0, 1)] == [5, 5]
    spaces = _labels(store, "space_id")
    assert (spaces[-3:] == -1).all() and (spaces[:-3] >= 0).all()
    assert parse.unassigned_points == 3
    assert distributed_ari(store) >= 0.95


def test_an_open_l_shaped_room_stays_one_space(tmp_path):
    # an L of two clear areas with no wall between them, and a room in the corner of the L behind a wall
    plan = Plan([Room(0, 0, 10, 4), Room(0, 4, 4, 9), Room(4.2, 4.2, 10, 9)], [(0, 2, 2.0, 0.9)])
    xyz, gt = sample(plan, density=200.0, seed=3)
    gt = np.where(gt == 1, 0, gt)  # rooms 0 and 1 are one open space
    store = write_store(tmp_path / "l.zarr", transform(xyz, 12.0), gt)
    parse = parse_spaces(store)
    assert len(parse.spaces) == 2
    assert distributed_ari(store) >= 0.95


def test_geojson_and_floor_plan(tmp_path, corridor, client):
    from engine.outputs.floorplan import draw_floorplan, floorplan_raster

    store, parse = corridor
    gj = write_spaces_geojson(parse, tmp_path / "out" / "spaces.geojson")
    fc = json.loads(open(gj).read())
    assert fc["type"] == "FeatureCollection" and len(fc["features"]) == len(parse.spaces)
    props = fc["features"][0]["properties"]
    assert {"id", "area_m2", "floor", "z_min", "z_max", "point_count"} <= set(props)
    png = draw_floorplan(store, parse, tmp_path / "out" / "floorplan.png", client=client)
    with open(png, "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    raster, _, pixel = floorplan_raster(store, parse, client=client)
    assert set(np.unique(raster)) - {-2} <= set(range(len(parse.spaces)))
    assert len(set(np.unique(raster)) - {-2}) == len(parse.spaces)


@pytest.fixture(scope="module")
def generated(tmp_path_factory, client):
    """A small generated building (engine.synth), as it is and turned by 30 degrees."""
    from engine.synth import generate

    root = tmp_path_factory.mktemp("synth")
    out = {}
    for yaw in (0.0, 30.0):
        path = root / f"b{int(yaw)}.zarr"
        generate(str(path), seed=3, area_m2=260, floors=1, density=400, yaw=yaw, offset=(2000.0, 1000.0, 5.0),
                 client=client)
        from tiles.store import open_store

        out[yaw] = open_store(str(path))
    return out


@pytest.mark.slow
def test_a_generated_building_reaches_ari_0_9(generated, client):
    store = generated[0.0]
    assert store.meta.point_count <= 1_200_000
    parse = parse_spaces(store, client=client)
    truth = len(store.doc("ground_truth")["spaces"])
    assert abs(len(parse.spaces) - truth) <= 1
    final = distributed_ari(store, client=client)
    assert final >= 0.9
    assert distributed_ari(store, pred="cell_id", client=client) <= final + 1e-9


@pytest.mark.slow
def test_the_generated_building_turned_by_30_degrees_gives_the_same_number_of_spaces(generated, client):
    a = parse_spaces(generated[0.0], client=client)
    b = parse_spaces(generated[30.0], client=client)
    assert len(a.spaces) == len(b.spaces)
    assert abs((math.degrees(b.frame.yaw) - math.degrees(a.frame.yaw) - 30.0 + 45) % 90 - 45) < 0.1
    assert distributed_ari(generated[30.0], client=client) >= 0.9


@pytest.fixture(scope="module")
def four_rooms(tmp_path_factory, client):
    """A small generated building of four rooms (engine.synth), with its per-point classes."""
    from engine.synth import generate
    from tiles.store import open_store

    path = tmp_path_factory.mktemp("rooms") / "r.zarr"
    generate(str(path), seed=63, rooms=4, density=500, client=client)
    return open_store(str(path))


def _room_cut_out(store, *, crop: bool) -> tuple[np.ndarray, np.ndarray]:
    """The points of the largest room of a generated store; without its floor and ceiling when ``crop``."""
    # world coordinates in metres (``store.read`` gives the raw integers: as metres they spread 99 k points over
    # 80 km and so over as many 10 m tiles, which is what made this test look hung)
    xyz = np.concatenate([store.xyz(t, local=False) for t in store.tiles])
    cols = [store.read(t, ["gt_space", "gt_class"]) for t in store.tiles]
    space = np.concatenate([c["gt_space"] for c in cols])
    cls = np.concatenate([c["gt_class"] for c in cols])
    ids, n = np.unique(space[space > 0], return_counts=True)
    keep = space == ids[np.argmax(n)]
    if crop:
        keep &= ~np.isin(cls, [0, 1])  # S3DIS codes: 0 ceiling, 1 floor
    return xyz[keep], np.zeros(int(keep.sum()), dtype=np.int32)


@pytest.mark.parametrize("crop", [False, True])
def test_one_room_parses_into_one_space_with_or_without_its_floor_and_ceiling(tmp_path, four_rooms, client, crop):
    # users often crop floors and ceilings away before a segmentation; without them the gaps between pieces of
    # furniture (and between beams and lamps above) looked like walls' voids: this room became 10 spaces
    xyz, gt = _room_cut_out(four_rooms, crop=crop)
    store = write_store(tmp_path / "room.zarr", xyz, gt, client=client)
    parse = parse_spaces(store, client=client)
    assert parse.stats["storeys_without_floor"] == ([0] if crop else [])
    assert len(parse.spaces) == 1
