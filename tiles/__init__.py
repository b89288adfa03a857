"""The Zarr tile store of a building: ingest, layout, export.

A store is one Zarr v3 group per building: points bucketed into a regular XY grid
of tiles, one group per tile, one array per point dimension.  See
:mod:`tiles.schema` for the metadata document and :mod:`tiles.store` for access.
"""
import tiles.config  # noqa: F401  (registers the dask.config defaults)
from tiles.errors import UserError
from tiles.store import TileStore, open_store

__all__ = ["TileStore", "UserError", "open_store"]
