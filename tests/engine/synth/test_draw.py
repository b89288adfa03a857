"""The PNG plan: written atomically, one panel per floor."""
from __future__ import annotations

import os

import matplotlib.image as mpimg

from engine.synth.draw import draw_plan


def test_png_is_written(building, tower, tmp_path):
    one = draw_plan(building, str(tmp_path / "one.png"))
    two = draw_plan(tower, str(tmp_path / "sub" / "two.png"), counts={"spaces": {0: 10}, "elements": {}})
    for p in (one, two):
        assert open(p, "rb").read(8) == b"\x89PNG\r\n\x1a\n"
        assert os.path.getsize(p) > 20_000
    a, b = mpimg.imread(one), mpimg.imread(two)
    assert b.shape[0] > a.shape[0]  # two floors, two panels stacked
    # not blank: spaces are filled with several colours
    assert len({tuple(px) for px in a[::7, ::7, :3].reshape(-1, 3).round(2)}) > 20
    assert sorted(os.listdir(tmp_path)) == ["one.png", "sub"]
