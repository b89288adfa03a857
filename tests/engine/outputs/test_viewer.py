"""The 3D view: an even sample per space, a self-contained page, and a page that renders in a real browser."""
from __future__ import annotations

import os
import shutil
import subprocess
from types import SimpleNamespace

import numpy as np
import pytest

from engine.outputs.viewer import sample_rates, space_outlines, viewer_points, viewer_summary, write_viewer


def test_spaces_share_the_budget_evenly_and_small_spaces_keep_all_their_points():
    rates = sample_rates({0: 100, 1: 10_000, 2: 50_000}, 3000)
    assert rates[0] == 1.0
    assert rates[1] * 10_000 == pytest.approx(1450) and rates[2] * 50_000 == pytest.approx(1450)
    assert sample_rates({0: 10, 1: 20}, 1000) == {0: 1.0, 1: 1.0}


class _Store:
    """Two tiles of a building with two spaces (a big one, a small one) and points outside both."""

    def __init__(self):
        rng = np.random.default_rng(0)
        self.cols = {}
        for t in ("a", "b"):
            n = 40_000
            space = rng.choice([0, 1, -1], n, p=[0.9, 0.05, 0.05]).astype(np.int32)
            self.cols[t] = {"xyz": rng.uniform(0, 10, (n, 3)), "space_id": space,
                            "classification": rng.integers(0, 13, n).astype(np.uint8),
                            "red": rng.integers(0, 256, n).astype(np.uint16),
                            "green": np.zeros(n, np.uint16), "blue": np.zeros(n, np.uint16)}
        self.tiles = [SimpleNamespace(name="a"), SimpleNamespace(name="b")]
        self.meta = SimpleNamespace(color_depth=8, names=lambda: ["red", "green", "blue"])

    def read(self, tile, names):
        return {k: self.cols[tile][k] for k in names}

    def xyz(self, tile, local=True):
        return self.cols[tile]["xyz"]


def test_the_sample_is_even_per_space_and_the_same_every_time():
    store = _Store()
    counts = {s: int(sum((c["space_id"] == s).sum() for c in store.cols.values())) for s in (0, 1, -1)}
    pts = viewer_points(store, counts, 6000)
    per = viewer_summary(pts)["per_space"]
    assert abs(per[0] - 2000) < 150 and abs(per[1] - 2000) < 150 and abs(per[-1] - 2000) < 150
    again = viewer_points(store, counts, 6000)
    assert all(np.array_equal(pts[k], again[k]) for k in pts)
    assert pts["rgb"].shape == (len(pts["xyz"]), 3) and pts["rgb"][:, 0].max() > 200


def _layer():
    ring = [[0, 0], [4, 0], [4, 3], [0, 3], [0, 0]]
    return {"type": "FeatureCollection", "features": [
        {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [ring]},
         "properties": {"id": 0, "floor": 0, "z_min": 0.0, "z_max": 2.8}}]}


def _page(tmp_path):
    rng = np.random.default_rng(1)
    n = 5000
    pts = {"xyz": rng.uniform([0, 0, 0], [4, 3, 2.8], (n, 3)).astype(np.float32),
           "space": np.zeros(n, np.int32), "cls": rng.integers(0, 13, n).astype(np.uint8),
           "rgb": rng.integers(0, 256, (n, 3)).astype(np.uint8)}
    elements = [{"class": "table", "element_id": 3, "space_id": 0, "score": 1.2, "center": [2, 1.5, 0.4],
                 "size": [1.2, 0.8, 0.8], "yaw": 0.3}]
    return write_viewer(tmp_path / "viewer.html", pts, elements, _layer())


def test_the_page_is_self_contained(tmp_path):
    html = open(_page(tmp_path), encoding="utf-8").read()
    assert "<script src=" not in html.replace('<script src="data:', "")  # plotly.js is inlined, no CDN
    assert "Plotly.newPlot" in html and '"table boxes"' in html and '"space 0"' in html
    assert "table #3" in html  # the box's hover text
    assert space_outlines(_layer())[0]["height"] == pytest.approx(2.8)


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")


@pytest.mark.skipif(_chromium() is None, reason="no Chromium on this machine (.ci/run installs Debian's chromium)")
def test_the_page_renders_a_non_blank_canvas_in_headless_chromium(tmp_path):
    from PIL import Image

    page = _page(tmp_path)
    shot = tmp_path / "shot.png"
    cmd = [_chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
           "--use-angle=swiftshader", "--disable-background-networking", "--disable-component-update",
           "--disable-sync", "--no-first-run", f"--user-data-dir={tmp_path / 'profile'}", "--window-size=1000,700",
           "--virtual-time-budget=10000", "--enable-logging=stderr", "--v=0", f"--screenshot={shot}",
           "file://" + os.path.abspath(page)]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    console = [line for line in res.stderr.splitlines() if "CONSOLE" in line or "Uncaught" in line]
    assert not [c for c in console if "rror" in c or "Uncaught" in c], console
    img = np.asarray(Image.open(shot).convert("RGB"))
    scene = img[100:600, 50:750].reshape(-1, 3)  # the WebGL scene, left of the legend
    colours = len(np.unique(scene, axis=0))
    assert colours > 50, f"the scene looks blank ({colours} colours)"
