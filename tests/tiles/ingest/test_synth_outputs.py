"""The readers on the synthetic generator's outputs: its LAZ and its S3DIS layout give the same labelled points."""
from __future__ import annotations

import numpy as np
import pytest

from engine.cli import main
from tiles.export import gather_points
from tiles.ingest import ingest


@pytest.fixture(scope="module")
def generated(tmp_path_factory, client):
    out = tmp_path_factory.mktemp("synth")
    sched = ["--scheduler", client.scheduler.address]
    common = ["--rooms", "3", "--density", "150", "--seed", "5", *sched]
    if main(["synth", str(out / "b.laz"), *common]) != 0 or \
            main(["synth", str(out / "s3"), "--format", "s3dis", *common]) != 0:
        pytest.skip("the synthetic generator did not run")
    return out


def test_generated_laz_and_s3dis_layout_ingest_to_the_same_labelled_points(generated, tmp_path):
    laz = ingest([str(generated / "b.laz")], str(tmp_path / "laz.zarr"))
    s3 = ingest([str(generated / "s3")], str(tmp_path / "s3.zarr"))
    assert laz.meta.point_count == s3.meta.point_count > 0
    assert laz.meta.names("ground_truth") == s3.meta.names("ground_truth") == ["gt_space", "gt_class", "gt_instance"]
    a, b = gather_points(laz), gather_points(s3)

    from scipy.spatial import cKDTree

    def world(p, store):
        return np.stack([p[c] * store.meta.scale[i] + store.meta.offset[i] for i, c in enumerate("xyz")], axis=1)

    np.testing.assert_array_equal(np.bincount(a["gt_class"], minlength=13), np.bincount(b["gt_class"], minlength=13))
    dist, nearest = cKDTree(world(a, laz)).query(world(b, s3))
    assert dist.max() < 0.0011  # the S3DIS text keeps 3 decimals
    assert np.mean(a["gt_class"][nearest] == b["gt_class"]) > 0.995
    assert laz.doc("ground_truth") is not None and s3.doc("ground_truth") is not None
    assert len(laz.doc("ground_truth")["spaces"]) == len(s3.doc("ground_truth")["spaces"])
