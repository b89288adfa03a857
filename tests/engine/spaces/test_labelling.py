"""The labels of space parsing in a tile: the points of a refined space located in its new cells."""
from __future__ import annotations

import numpy as np

from engine.spaces.alignment import Frame
from engine.spaces.histograms import Grid
from engine.spaces.labelling import relabel
from engine.spaces.part import Part
from engine.spaces.refine import Refinement


def test_relabel_moves_only_the_refined_spaces_points_into_the_new_cells():
    from engine.spaces.slicing import Box

    scale, offset, origin = (0.01, 0.01, 0.01), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    # four points: two in building cell 0 (refined), one in cell 1 (not), one outside every cell
    raw = {"x": np.array([100, 300, 500, 700]), "y": np.array([50, 50, 50, 50]), "z": np.array([100, 100, 100, 100])}
    cell = np.array([0, 0, 1, -1])
    grid = Grid(Frame(0.0, origin), 0.01, 0.02)
    part = Part(0.0, [Box(0, 0, 200, 0, 100), Box(0, 200, 400, 0, 100)], np.array([0, 1]))
    ref = Refinement(7, 0, [part])
    idx = part.index((0, 200))
    owner = np.array([-1, 0, -1])  # owner[cell + 1]: building cell 0 belongs to refinement 0
    new = relabel(cell, raw, type("M", (), {"scale": scale, "offset": offset, "origin": origin})(),
                  [(ref, [(grid, idx, 10)])], owner)
    assert new.tolist() == [10, 11, 1, -1]
