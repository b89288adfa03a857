"""The encoder reference of issue 29 item 4: laspy re-encoding the same points, and the export's ratio to it."""
from __future__ import annotations

import numpy as np

from benchmarks.encode_reference import encode_row, encode_seconds


def test_the_ratio_is_one_of_medians_against_the_target():
    row = encode_row([9.0, 3.0, 4.0], [1.0, 2.0, 100.0])
    assert row["seconds"] == 4.0 and row["encode_s"] == 2.0 and row["x_encode"] == 2.0 and row["met"]
    assert not encode_row([5.0], [2.0])["met"]


def test_encode_seconds_writes_the_same_points_and_leaves_no_file(tmp_path):
    import laspy

    las = laspy.create(point_format=6, file_version="1.4")
    las.x, las.y, las.z = (np.arange(1000, dtype=float) * k for k in (0.01, 0.02, 0.03))
    src = tmp_path / "points.laz"
    las.write(str(src))
    seconds = encode_seconds(str(src), str(tmp_path))
    assert seconds > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["points.laz"]
