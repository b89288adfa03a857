"""E57 ingest: every scan with its pose applied, invalid records counted, streamed in parts."""
from __future__ import annotations

import numpy as np
import pytest

from tiles.export import gather_points
from tiles.ingest import ingest

pye57 = pytest.importorskip("pye57")


def _quaternion_z(angle):
    return np.array([np.cos(angle / 2), 0.0, 0.0, np.sin(angle / 2)])


def _write_e57(path, seed=0):
    """Two structured scans with colour, intensity, grid indices, some invalid records and different poses."""
    rng = np.random.default_rng(seed)
    scans = []
    with pye57.E57(str(path), mode="w") as e:
        for k, (angle, shift) in enumerate([(0.3, [10.0, 5.0, 1.0]), (-1.2, [2.0, -4.0, 0.5])]):
            rows, cols = 40, 30 + 10 * k
            n = rows * cols
            data = {
                "cartesianX": rng.uniform(-5, 5, n), "cartesianY": rng.uniform(-5, 5, n),
                "cartesianZ": rng.uniform(0, 3, n),
                "intensity": rng.uniform(0, 1, n),
                "colorRed": rng.integers(0, 256, n).astype(np.uint8),
                "colorGreen": rng.integers(0, 256, n).astype(np.uint8),
                "colorBlue": rng.integers(0, 256, n).astype(np.uint8),
                "rowIndex": np.repeat(np.arange(rows), cols).astype(np.int32),
                "columnIndex": np.tile(np.arange(cols), rows).astype(np.int32),
                "cartesianInvalidState": (rng.uniform(0, 1, n) < 0.1).astype(np.int8) * 2,
            }
            e.write_scan_raw(data, rotation=_quaternion_z(angle), translation=np.array(shift), name=f"scan {k}")
            scans.append(data)
    return scans


def test_scans_are_read_with_their_pose_in_parts(tmp_path):
    path = tmp_path / "two.e57"
    _write_e57(path)
    with pytest.warns(UserWarning, match="flagged invalid"):
        s = ingest([str(path)], str(tmp_path / "s.zarr"), part_points=500)
    ref = pye57.E57(str(path))
    expected = [ref.read_scan(i, intensity=True, colors=True, row_column=True, transform=True) for i in range(2)]
    n_valid = sum(len(d["cartesianX"]) for d in expected)
    assert s.meta.point_count == n_valid
    assert len(s.meta.parts) == 3 + 4  # 1200 and 1600 records in parts of 500
    got = gather_points(s)
    xyz = np.stack([got[a] * 1e-4 + o for a, o in zip("xyz", s.meta.offset)], axis=1)
    want = np.concatenate([np.stack([d["cartesianX"], d["cartesianY"], d["cartesianZ"]], axis=1) for d in expected])
    np.testing.assert_allclose(xyz, want, atol=6e-5)
    np.testing.assert_array_equal(got["red"], np.concatenate([d["colorRed"] for d in expected]))
    np.testing.assert_array_equal(got["row_index"], np.concatenate([d["rowIndex"] for d in expected]))
    np.testing.assert_array_equal(got["scan_index"], np.repeat([0, 1], [len(d["cartesianX"]) for d in expected]))
    info = s.meta.sources[0].info
    assert info["invalid_records"] == 2800 - n_valid > 0
    assert [sc["structured"] for sc in info["scans"]] == [True, True]
    assert s.meta.color_depth == 8 and s.meta.dimension("intensity").dtype == "uint16"


def test_missing_pye57_gives_a_clear_error(tmp_path, monkeypatch):
    import builtins

    from tiles.errors import UserError

    path = tmp_path / "one.e57"
    _write_e57(path)
    real_import = builtins.__import__

    def no_pye57(name, *a, **k):
        if name == "pye57":
            raise ImportError("no pye57")
        return real_import(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_pye57)
    with pytest.raises(UserError, match=r"pip install 'buildingparser\[e57\]'"):
        ingest([str(path)], str(tmp_path / "s.zarr"))


def test_e57_store_exports_its_scan_dimensions(tmp_path):
    import laspy

    from tiles.export import export

    _write_e57(tmp_path / "a.e57", seed=1)
    with pytest.warns(UserWarning):
        s = ingest([str(tmp_path / "a.e57")], str(tmp_path / "s.zarr"))
    export(s, str(tmp_path / "a.laz"))
    out = laspy.read(str(tmp_path / "a.laz"))
    got = gather_points(s)
    assert out.point_format.id == 7
    for name in ("scan_index", "row_index", "column_index"):
        np.testing.assert_array_equal(out.points.array[name], got[name])
    np.testing.assert_array_equal(np.asarray(out.intensity), got["intensity"])
    np.testing.assert_array_equal(np.asarray(out.red) // 257, got["red"])


SHARED_E57 = __import__("pathlib").Path(__file__).resolve().parents[3] / ".." / "shared" / "data" / "e57"


@pytest.mark.parametrize("name", ["bunnyFloat.e57", "pumpA.e57"])
def test_every_shared_e57_file_ingests_with_all_its_valid_points(tmp_path, name):
    """Scaled-integer and float fields, intensity limits of any node type (pumpA: ScaledIntegerNode), poses."""
    path = SHARED_E57 / name
    if not path.exists():
        pytest.skip(f"{path} is absent (the shared E57 reference files are not on this machine)")
    s = ingest([str(path)], str(tmp_path / "s.zarr"))
    ref = pye57.E57(str(path))
    scans = [ref.read_scan_raw(i) for i in range(ref.scan_count)]
    valid = [d.get("cartesianInvalidState", np.zeros(len(d["cartesianX"]))) == 0 for d in scans]
    assert s.meta.point_count == sum(int(v.sum()) for v in valid) > 0
    info = s.meta.sources[0].info
    assert info["invalid_records"] == sum(len(v) - int(v.sum()) for v in valid)
    got = gather_points(s)
    want = np.concatenate([
        np.stack([d[k][v] for k in ("cartesianX", "cartesianY", "cartesianZ")], axis=1) @ ref.get_header(i).rotation_matrix.T
        + ref.get_header(i).translation for i, (d, v) in enumerate(zip(scans, valid))])
    xyz = np.stack([got[a] * 1e-4 + o for a, o in zip("xyz", s.meta.offset)], axis=1)
    np.testing.assert_allclose(xyz, want, atol=6e-5)
    if "intensity" in scans[0]:
        lo, hi = info["scans"][0]["intensity_limits"]
        expected = np.clip(np.rint((scans[0]["intensity"][valid[0]] - lo) / (hi - lo) * 65535), 0, 65535)
        np.testing.assert_allclose(got["intensity"], expected, atol=1)  # float rounding at .5


class _Scaled:
    def __init__(self, v):
        self.v = v

    def scaledValue(self):  # noqa: N802 - libe57's name
        return self.v


class _Plain(_Scaled):
    scaledValue = None  # type: ignore[assignment]

    def value(self):
        return self.v


class _Group(dict):
    def isDefined(self, name):  # noqa: N802 - libe57's name
        return name in self


@pytest.mark.parametrize("node", [_Scaled, _Plain])
def test_intensity_limits_of_any_node_type(node):
    from tiles.ingest.e57 import limits_of

    scan = _Group(intensityLimits=_Group(intensityMinimum=node(2.0), intensityMaximum=node(10.0)))
    assert limits_of(scan, "intensityLimits", "intensity") == [2.0, 10.0]
    assert limits_of(_Group(), "intensityLimits", "intensity") is None
    flat = _Group(intensityLimits=_Group(intensityMinimum=node(3.0), intensityMaximum=node(3.0)))
    assert limits_of(flat, "intensityLimits", "intensity") is None  # no range: values are rounded as they are


def test_a_pose_with_a_bad_quaternion_is_refused_in_one_line(tmp_path):
    from tiles.errors import UserError

    path = tmp_path / "bad.e57"
    with pye57.E57(str(path), mode="w") as e:
        e.write_scan_raw({"cartesianX": np.zeros(3), "cartesianY": np.ones(3), "cartesianZ": np.arange(3.0)},
                         rotation=np.zeros(4), translation=np.zeros(3))
    with pytest.raises(UserError, match="pose rotation is not a quaternion"):
        ingest([str(path)], str(tmp_path / "s.zarr"))
    assert not (tmp_path / "s.zarr").exists()
