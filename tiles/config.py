"""Defaults of the ``buildingparser.*`` settings this package reads, registered with ``dask.config``.

Override them like any dask setting: ``dask.config.set({"buildingparser.tiles.size": 20})``,
a YAML file in ``~/.config/dask/``, or ``DASK_BUILDINGPARSER__TILES__SIZE=20``.
"""
from __future__ import annotations

import os

import dask.config
import yaml

_FILE = os.path.join(os.path.dirname(__file__), "tiles.yaml")


def register() -> None:
    """Merge this package's defaults under the user's settings (idempotent)."""
    with open(_FILE) as f:
        defaults = yaml.safe_load(f)
    dask.config.update_defaults(defaults)


register()
