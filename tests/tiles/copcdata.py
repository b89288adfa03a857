"""A small surface cloud and its tile store for the COPC tests, and helpers to compare records and read nodes."""
from __future__ import annotations

import laspy
import numpy as np
from laspy.copc import CopcReader

from tiles.copc import ENTRY
from tiles.ingest import ingest
from tiles.schema import Dimension
from tiles.store import TileStore


def cloud(path, n=6000, seed=3):
    """Walls and a floor (a surface cloud, dense in one corner) with GPS times, colours and classes."""
    rng = np.random.default_rng(seed)
    las = laspy.LasData(laspy.LasHeader(point_format=7, version="1.4"))
    las.header.scales = np.array([0.001] * 3)
    las.header.offsets = np.array([1000.0, 2000.0, 0.0])
    u = rng.uniform(0, 1, (n, 3))
    side = rng.integers(0, 3, n)
    x = np.where(side == 0, 0.0, u[:, 0] * 20)
    y = np.where(side == 1, 0.0, u[:, 1] * 12)
    z = np.where(side == 2, 0.0, u[:, 2] * 3)
    dense = rng.uniform(0, 1, n) < 0.4  # a dense patch: deeper levels there
    x[dense], y[dense] = 1 + u[dense, 0] * 0.5, 1 + u[dense, 1] * 0.5
    las.x, las.y, las.z = 1000 + x, 2000 + y, z
    las.gps_time = rng.uniform(10, 20, n)
    las.red = rng.integers(0, 65535, n)
    las.classification = rng.integers(0, 20, n)
    las.intensity = np.arange(n) % 65536
    las.write(str(path))
    return las


def copc_store(d) -> TileStore:
    """The cloud ingested (5 m tiles) with a class code and a space id per point."""
    cloud(d / "in.las")
    st = ingest([str(d / "in.las")], str(d / "s.zarr"), part_points=1000, tile_size=5.0)
    for t in st.tiles:
        pi = st.read(t, ["point_index"])["point_index"]
        st.write_array(t, "classification", (pi % 13).astype(np.uint8))
        st.write_array(t, "space_id", (pi // 500).astype(np.int32))
    st.add_dimensions([Dimension("classification", "uint8", "result", "class code"),
                       Dimension("space_id", "int32", "result", "space id")])
    return st


#: Small enough that 6000 points make several levels, groups and top nodes
OPTS = {"node_points": 150, "group_points": 900, "grid_bits": 2}


def rows(arr):
    """The records as sortable rows of bytes (a multiset compare of every field)."""
    v = np.ascontiguousarray(arr).view(f"V{arr.dtype.itemsize}")
    return np.sort(v)


def node_entries(path):
    with CopcReader.open(str(path)) as r:
        info = r.copc_info
        with open(path, "rb") as f:
            f.seek(info.hierarchy_root_offset)
            page = f.read(info.hierarchy_root_size)
        r.header.vlrs.append(r.laszip_vlr)
        return r.header, info, [ENTRY.unpack_from(page, i) for i in range(0, len(page), ENTRY.size)]
