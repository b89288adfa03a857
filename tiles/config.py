"""Defaults of the ``buildingparser.*`` settings this package reads, registered with ``dask.config``.

Override them like any dask setting: ``dask.config.set({"buildingparser.tiles.size": 20})``,
a YAML file in ``~/.config/dask/``, or ``DASK_BUILDINGPARSER__TILES__SIZE=20``.  The
environment of the dask worker processes (glibc's memory settings) is set here too.
"""
from __future__ import annotations

import os

import dask.config
import yaml

_FILE = os.path.join(os.path.dirname(__file__), "tiles.yaml")


def register() -> None:
    """Merge this package's defaults under the user's settings (idempotent).

    Besides ``buildingparser.*``, ``tiles.yaml`` sets the environment of dask's
    worker processes (``distributed.nanny.pre-spawn-environ``): distributed's own
    defaults are registered first so that these replace them (the defaults
    registered last win; a user's setting wins over both).
    """
    import distributed.config  # noqa: F401 - distributed's defaults before ours

    with open(_FILE) as f:
        defaults = yaml.safe_load(f)
    dask.config.update_defaults(defaults)


register()
