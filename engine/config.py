"""Defaults of the engine's ``buildingparser.*`` settings, registered with ``dask.config``.

Every tunable of the pipeline is a ``dask.config`` key under ``buildingparser``;
see the YAML files next to this module and next to :mod:`tiles.config`.
"""
from __future__ import annotations

import glob
import os

import dask.config
import yaml

import tiles.config  # noqa: F401  (the tiles' own defaults)

_HERE = os.path.dirname(__file__)


def register() -> None:
    """Merge the engine's defaults (every ``engine/**/*.yaml``) under the user's settings."""
    for path in sorted(glob.glob(os.path.join(_HERE, "**", "*.yaml"), recursive=True)):
        with open(path) as f:
            dask.config.update_defaults(yaml.safe_load(f) or {})


def get(key: str, default=None):
    """A ``buildingparser.<key>`` setting."""
    return dask.config.get(f"buildingparser.{key}", default)


register()
