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
#: The streams of the ``subsampled``, ``windows``, ``doors`` and ``furniture`` style families.
S_SUBSAMPLE, S_WINDOWS, S_DOORS, S_FURNITURE = 5, 6, 7, 8
#: The style families a building may draw from, beyond ``classic`` (the shipped model's training buildings):
#: ``varied`` (boards bare or with a tray, and each room's scan character: :mod:`engine.synth.furniture`,
#: :func:`engine.synth.colours.vary_scan`), ``subsampled`` (each room's scan voxel-subsampled on a grid of its
#: own: :func:`engine.synth.colours.subsample_scan`), ``windows`` (each exterior wall's window type:
#: :func:`engine.synth.openings.window_type`), ``doors`` (each door's type: :func:`engine.synth.frames.door_type`)
#: and ``furniture`` (each chair's shape: :mod:`engine.synth.chairs`).  Each family has its own stream, so that
#: families combine (``"varied,windows"``) and a building's other draws stay the classic building's.
FAMILIES = ("varied", "subsampled", "windows", "doors", "furniture")


def style_families(styles: str) -> tuple[str, ...]:
    """The families of a style: ``"classic"`` -> ``()``, ``"windows,varied"`` -> ``("varied", "windows")``
    (in :data:`FAMILIES`' order); :class:`ValueError` names an unknown one."""
    names = [s.strip() for s in str(styles).split(",") if s.strip()]
    if names == ["classic"]:
        return ()
    bad = [s for s in names if s not in FAMILIES]
    if bad or not names:
        raise ValueError(f"styles must be classic or a comma-separated combination of {', '.join(FAMILIES)}, "
                         f"not {styles!r}")
    return tuple(f for f in FAMILIES if f in names)


def style_name(families: tuple[str, ...]) -> str:
    """The canonical name of a combination of families (``"classic"`` for none)."""
    return ",".join(families) or "classic"

#: Average floor area per space, used to turn ``rooms`` into an area.
AREA_PER_SPACE = 31.0
MIN_AREA_PER_FLOOR = 40.0


def rng_for(seed: int, *key: int) -> np.random.Generator:
    """The random stream of one stage of one object, independent of every other."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=tuple(int(k) for k in key)))
