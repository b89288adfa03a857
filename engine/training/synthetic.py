"""Generated training buildings (:mod:`engine.synth`): their seeded yaw, and their generation into tile stores.

``train`` and ``train-crf`` generate their buildings the same way, so that seed ``S`` is the same
building for both (and for ``synth --training-yaw``).
"""
from __future__ import annotations

import logging
import os
from typing import Any

import numpy as np

from engine.synth import generate
from tiles.store import open_store

logger = logging.getLogger(__name__)


def synthetic_yaw(seed: int) -> float:
    """The yaw (degrees) of generated training building ``seed``: seeded, so that frames are exercised."""
    return float(np.random.default_rng([int(seed), 7]).uniform(0.0, 90.0))


def generate_buildings(where: str, first_seed: int, n: int, area: float, *, density: float | None = None,
                       client=None, styles: str = "classic") -> tuple[list[Any], list[str]]:
    """Generate ``n`` training buildings, seeds ``first_seed`` on, into ``where/synthetic-<seed>.zarr``.

    Parameters
    ----------
    where
        The folder of the tile stores (created if need be).
    first_seed, n
        The first seed and how many buildings.
    area
        The floor area of each building (m^2).
    density
        Points per m^2 of scanned surface; None: ``buildingparser.synth.density``.
    client
        A ``distributed.Client``; None generates here.
    styles
        The buildings' styles (:func:`engine.synth.generate`): ``classic`` or style families (``varied,windows``).

    Returns
    -------
    stores, names
        The opened stores and their stable names (``"synthetic seed S"``).
    """
    os.makedirs(where, exist_ok=True)
    stores, names = [], []
    for i in range(n):
        seed = first_seed + i
        out = os.path.join(where, f"synthetic-{seed}.zarr")
        yaw = synthetic_yaw(seed)
        logger.info(f"generating building {i + 1}/{n} (seed {seed}, about {area:g} m2, yaw {yaw:.1f} deg, "
                    f"{styles} styles)")
        generate(out, seed=seed, area_m2=area, density=density, yaw=yaw, client=client, overwrite=True,
                 styles=styles)
        stores.append(open_store(out))
        names.append(f"synthetic seed {seed}")
    return stores, names
