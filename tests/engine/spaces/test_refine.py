"""Refinement of large spaces in their own frame, end to end: a wing at an angle cut into its rooms, and the
refinement on the cluster (points gathered per tile, passes over pieces) equal to the serial one."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from engine.metrics.ari import distributed_ari
from engine.spaces.document import SpaceParse
from engine.spaces.parse import parse_spaces
from engine.spaces.settings import SpaceSettings


@pytest.fixture(scope="module")
def winged(tmp_path_factory, client):
    """A small generated building with a wing at an angle to the rest (engine.synth, difficulty ``wing``)."""
    from engine.synth import generate
    from tiles.store import open_store

    path = tmp_path_factory.mktemp("wing") / "w.zarr"
    generate(str(path), seed=4, area_m2=200, floors=1, density=150, yaw=10.0, hardness="wing", client=client)
    return open_store(str(path))


@pytest.mark.slow
def test_refinement_on_the_cluster_equals_the_serial_one(winged, client, monkeypatch):
    """Refined spaces read by one task per tile, largest first, their histogram passes run as tasks over
    pieces of their points on the workers (refine-pieces-points), with the bins kept by the memory stores,
    give the parse of the serial refinement that reads each space in one go and computes the bins per pass."""
    import dask
    from distributed import get_task_stream

    import engine.spaces.memory_store as memory_store

    def parsed():
        return ({k: v for k, v in p.to_doc().items() if k != "stats"},
                [winged.read(t.name, ["cell_id", "space_id"]) for t in winged.tiles])

    def passes(stream) -> int:
        return sum(str(t.get("key", "")).startswith(("segment_histograms", "edge_histograms")) for t in stream)

    with dask.config.set({"buildingparser.spaces.refine-pieces-points": 0}), get_task_stream(client) as ts:
        p = parse_spaces(winged, client=client)  # the refinements' passes in their own tasks
    in_task = passes(ts.data)
    with dask.config.set({"buildingparser.spaces.refine-pieces-points": 1}), get_task_stream(client) as ts:
        p = parse_spaces(winged, client=client)
    assert p.stats["refined"], "the wing is refined"
    assert passes(ts.data) > in_task  # the refinements' passes ran as tasks over pieces
    fast = parsed()
    monkeypatch.setattr(memory_store.MemoryStore, "cached_bins", None)  # Grid.tile_bins computes them every pass
    p = parse_spaces(winged, client=None)
    slow = parsed()
    assert fast[0] == slow[0]
    assert all(np.array_equal(a[c], b[c]) for a, b in zip(fast[1], slow[1]) for c in ("cell_id", "space_id"))


@pytest.mark.slow
def test_a_wing_at_an_angle_is_cut_into_its_rooms(winged, client):
    # without the refinement the wing's walls smear in the building's frame: the whole wing is one cell
    before = parse_spaces(winged, client=client, params=SpaceSettings.from_config(refine_min_area=0.0))
    ari_before = distributed_ari(winged, client=client)
    parse = parse_spaces(winged, client=client)
    ari = distributed_ari(winged, client=client)
    assert ari_before < 0.8 and ari >= 0.95
    assert len(parse.spaces) > len(before.spaces)
    turned = [c for c in parse.cells if c.yaw is not None]
    assert turned, "the wing's cells are in the wing's own frame"
    off = {round(((math.degrees(c.yaw - parse.frame.yaw) + 45) % 90 - 45), 1) for c in turned}
    assert all(abs(o) >= 10 for o in off)  # the generator turns a wing by 15-40 degrees
    # the document round-trips and every new space has a footprint within the building
    again = SpaceParse.from_doc(json.loads(json.dumps(parse.to_doc())))
    assert [c.yaw for c in again.cells] == [c.yaw for c in parse.cells]
    assert all(s.area_m2 > 0 for s in parse.spaces)
    assert sum(s.point_count for s in parse.spaces) + parse.unassigned_points == winged.meta.point_count
