"""What the parse cannot represent is refused in one line before any of its tasks (issue 26 items 1 and 2)."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import laspy
import numpy as np
import pytest

from engine.cli import main
from tiles.errors import UserError
from tiles.ingest import ingest

SHARED_SPARSE = os.path.join(os.path.dirname(__file__), "..", "..", "..", "..", "shared", "data", "las-samples",
                             "laspy", "simple.las")


def _las(path, xyz, scale=0.01):
    h = laspy.LasHeader(point_format=3, version="1.2")
    h.scales, h.offsets = [scale] * 3, [0.0] * 3
    las = laspy.LasData(h)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.write(str(path))
    return path


def test_a_cloud_spread_over_1e9_m_is_refused_quickly_under_a_memory_cap(tmp_path):
    """Was: MemoryError of 284 PiB and a traceback. Now: ingest by occupied tiles, then one line."""
    rng = np.random.default_rng(0)
    src = _las(tmp_path / "huge.las", rng.uniform(-1e9, 1e9, (300, 3)), scale=1.0)
    code = textwrap.dedent(f"""
        import resource, sys
        resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))  # 3 GiB of address space for the whole run
        from engine.cli import main
        sys.exit(main(["run", {str(src)!r}, "--out", {str(tmp_path / 'out')!r}, "--workers", "1"]))
    """)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    errors = [x for x in p.stderr.splitlines() if "error:" in x]
    assert p.returncode == 2 and len(errors) == 1 and "Traceback" not in p.stderr, p.stderr
    assert "too sparse to be a building interior: 300 points over" in errors[0]


def test_nan_and_inf_coordinates_are_refused_in_one_line(tmp_path):
    text = tmp_path / "nan.xyz"
    text.write_text("0 0 0\n1 nan 2\n3 4 inf\n")
    with pytest.raises(UserError, match=r"line 2: not a finite number \(NaN or infinity\)") as e:
        ingest([str(text)], str(tmp_path / "s.zarr"))
    assert "\n" not in e.value.line()
    from tiles.ingest.reader import Quantization

    with pytest.raises(UserError, match=r"scan.e57: 1 non-finite \(NaN or infinite\) z coordinates"):
        Quantization((1e-4,) * 3, (0.0,) * 3).quantize(np.array([[0.0, 0, 0], [1, 1, np.inf]]), "scan.e57")


def test_a_flat_cloud_is_refused_before_the_parse(tmp_path, capsys, client):
    rng = np.random.default_rng(1)
    xyz = np.column_stack([rng.uniform(0, 5, 20000), rng.uniform(0, 5, 20000), np.full(20000, 1.5)])
    src = _las(tmp_path / "flat.las", xyz)
    rc = main(["run", str(src), "--out", str(tmp_path / "out"), "--scheduler", client.scheduler.address])
    errors = [x for x in capsys.readouterr().err.splitlines() if "error:" in x]
    assert rc == 2 and len(errors) == 1 and "lie at one height: no floor and ceiling" in errors[0]
    assert not (tmp_path / "out" / "report.html").exists()


def test_sources_that_do_not_fit_one_grid_are_refused_in_one_line(tmp_path, client):
    """(Header bounds are not trusted for this: the laspy samples' headers hold bounds their points do not.)"""
    a = _las(tmp_path / "a.las", np.array([[0.0, 0, 0], [1, 1, 1]]), scale=0.0001)
    b = _las(tmp_path / "b.las", np.array([[0.0, 0, 0], [1e6, 1, 1]]), scale=0.01)  # fits its 1 cm grid only
    with pytest.raises(UserError, match=r"b.las: x coordinates do not fit the store's grid \(scale 0.0001"):
        ingest([str(a), str(b)], str(tmp_path / "s.zarr"), client=client)
    assert not (tmp_path / "s.zarr").exists()


def test_the_shared_sparse_las_sample_is_refused_with_its_density_before_its_tiles_are_written(tmp_path):
    if not os.path.exists(SHARED_SPARSE):
        pytest.skip(f"{SHARED_SPARSE} is absent (the shared LAS samples are not on this machine)")
    from engine.pipeline.plausible import check_cloud

    with pytest.raises(UserError, match=r"too sparse to be a building interior: 1,065 points over 3,362.7 x "
                                        r"4,635.7 x .* points per m2"):
        ingest([SHARED_SPARSE], str(tmp_path / "s.zarr"), accept=lambda facts: check_cloud(facts, SHARED_SPARSE))
    assert os.listdir(tmp_path) == []  # the store was abandoned before its tiles were written
