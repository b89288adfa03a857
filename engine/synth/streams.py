"""Random streams of the generator: one per stage of one object, independent of every other.

Every draw of :mod:`engine.synth` comes from ``rng_for(seed, stage, id...)``
(``numpy.random.SeedSequence(seed, spawn_key=(stage, id...))``), so nothing
depends on the order in which dask runs the tasks.
"""
from __future__ import annotations

import numpy as np

#: Random-stream keys (first element of every spawn_key).
S_BUILDING, S_FLOOR, S_SPACE, S_SCAN = 0, 1, 2, 3
#: The style variety's own streams (``styles="varied"``): a classic building's draws stay as they are.
S_VARIETY = 4
#: The style families: ``classic`` (the shipped model's training buildings) and ``varied`` (each element's style
#: drawn from its family: :mod:`engine.synth.furniture`).
STYLES = ("classic", "varied")

#: Average floor area per space, used to turn ``rooms`` into an area.
AREA_PER_SPACE = 31.0
MIN_AREA_PER_FLOOR = 40.0


def rng_for(seed: int, *key: int) -> np.random.Generator:
    """The random stream of one stage of one object, independent of every other."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=tuple(int(k) for k in key)))
