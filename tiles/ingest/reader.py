"""What every input reader shares: the reader interface, its parts, the store's grid, the store's dimensions.

A *reader* describes one source (a LAS file, a text file, an S3DIS area, an E57
file).  It is built on the driver, where it checks the source and learns its
dimensions, then sent to the workers inside each part's task: it must stay
small when pickled (paths and header facts, never point data).  File access is
in :mod:`tiles.ingest.files`.
"""
from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tiles.errors import UserError
from tiles.groundtruth import gt_dimensions
from tiles.schema import GT_DTYPES, Dimension

#: Dimensions whose values are fixed by the store or the pipeline: a source field of that name is renamed.
RESERVED_NAMES = frozenset({"x", "y", "z", "point_index", "part_offsets", "cell_id", "space_id",
                            "classification", "element_id"})
#: Fill value of a dimension for points of a source that lacks it (everything else: 0).
FILL_VALUES = {"gt_space": -1, "gt_class": 12, "gt_instance": -1}
_INT32 = np.iinfo(np.int32)


@dataclass(frozen=True)
class Quantization:
    """The store's coordinate grid: ``world = raw * scale + offset`` per axis."""

    scale: tuple[float, float, float]
    offset: tuple[float, float, float]

    def quantize(self, xyz: np.ndarray, path: str) -> dict[str, np.ndarray]:
        """World coordinates ``(n, 3)`` float64 to raw int32 columns; a clear error if they do not fit."""
        out: dict[str, np.ndarray] = {}
        for i, a in enumerate("xyz"):
            v = np.rint((xyz[:, i] - self.offset[i]) / self.scale[i])
            if not np.isfinite(v).all():
                bad = int(np.count_nonzero(~np.isfinite(xyz[:, i])))
                raise UserError(path, f"{bad:,} non-finite (NaN or infinite) {a} coordinates")
            if len(v) and (v.min() < _INT32.min or v.max() > _INT32.max):
                raise UserError(path, f"{a} coordinates span more than int32 steps of {self.scale[i]} m around "
                                      f"{self.offset[i]} m: the cloud is too large for this scale")
            out[a] = v.astype(np.int32)
        return out

    def requantize(self, raw: dict[str, np.ndarray], scale, offset, path: str,
                   axes: str = "xyz") -> tuple[dict[str, np.ndarray], float]:
        """Raw integers of another grid to this one; also the largest rounding error in metres.

        When this scale divides the other and the offsets differ by whole steps
        the mapping is exact integer arithmetic (error 0).  Only ``axes`` are
        converted (``raw`` needs only those).
        """
        out: dict[str, np.ndarray] = {}
        worst = 0.0
        for i, a in enumerate("xyz"):
            if a not in axes:
                continue
            s, o = float(scale[i]), float(offset[i])
            if s == self.scale[i] and o == self.offset[i]:
                out[a] = np.asarray(raw[a], dtype=np.int32)
                continue
            k = s / self.scale[i]
            m = (o - self.offset[i]) / self.scale[i]
            if abs(k - round(k)) < 1e-9 and abs(m - round(m)) < 1e-6:
                v = np.asarray(raw[a], dtype=np.int64) * int(round(k)) + int(round(m))
            else:
                world = np.asarray(raw[a], dtype=np.float64) * s + o
                v = np.rint((world - self.offset[i]) / self.scale[i])
                if len(v):
                    worst = max(worst, float(np.max(np.abs(v * self.scale[i] + self.offset[i] - world))))
            if len(v) and (v.min() < _INT32.min or v.max() > _INT32.max):
                raise UserError(path, f"{a} coordinates do not fit the store's grid (scale {self.scale[i]}, "
                                      f"offset {self.offset[i]}): ingest this file on its own")
            out[a] = v.astype(np.int32)
        return out, worst


@dataclass
class PartResult:
    """What reading one part gives: its columns and facts for the source report.

    A reader whose points come as one record array may instead give the
    records not yet unpacked (``records``), with ``columns`` holding only
    ``x`` and ``y`` on the store's grid and ``unpack(records)`` giving the
    full result of any reordering of them: the records are then sorted by tile
    whole (one gather) before they are unpacked, cheaper than one gather per
    column.
    """

    columns: dict[str, np.ndarray]
    stats: dict[str, Any] = field(default_factory=dict)
    records: np.ndarray | None = None
    unpack: Callable[[np.ndarray], PartResult] | None = None


class Reader:
    """One source.  Subclasses set the attributes in ``__init__`` (on the driver) and implement the methods.

    Attributes
    ----------
    path
        The source as given (normalised path or URL).
    format
        Short name (``las``, ``laz``, ``text``, ``s3dis``, ``e57``).
    dimensions
        The per-point arrays this source provides, ``x``, ``y``, ``z`` first.
    expected_count
        Points the source promises (from a header), or None when only reading tells.
    """

    path: str
    format: str
    dimensions: list[Dimension]
    expected_count: int | None = None
    storage_options: dict[str, Any] | None = None

    def native_grid(self) -> Quantization | None:
        """The source's own scale and offset (LAS), or None."""
        return None

    def first_point(self) -> np.ndarray | None:
        """A world point of the source, to place the offset of a store without a native grid."""
        return None

    def crs(self) -> dict[str, Any] | None:
        return None

    def las_facts(self) -> dict[str, Any] | None:
        """Header facts and records needed to write this source's LAS flavour back (LAS only)."""
        return None

    def restrict(self, bounds: Any) -> None:
        """Only the points inside ``bounds`` (:class:`tiles.ingest.bounds.Bounds`) are wanted: a reader that can
        skip the data outside (a COPC file's octree nodes) plans fewer reads; the parts are filtered anyway."""
        return None

    def plan(self, part_points: int) -> list[Any]:
        """Small picklable specs, one per task, in point order."""
        raise NotImplementedError

    def parts_of(self, spec: Any) -> int:
        """How many consecutive parts the task of ``spec`` writes (usually 1)."""
        return 1

    def read(self, spec: Any, grid: Quantization) -> Iterator[PartResult]:
        """The parts of one spec, in order, with x/y/z on ``grid``; runs on a worker."""
        raise NotImplementedError

    def source_info(self, stats: list[dict[str, Any]]) -> dict[str, Any]:
        """The report of this source for the store's metadata, from its parts' stats."""
        return {}

    def warnings(self, info: dict[str, Any]) -> list[str]:
        """One-line warnings for the user about this source (repairs, dropped records)."""
        return []


# -- dimensions -----------------------------------------------------------------------------

def safe_name(name: str, taken: set[str]) -> str:
    """A store array name for a source field: Zarr-safe, not reserved, not yet taken."""
    clean = "".join(c if (c.isalnum() or c in "_-.") else "_" for c in name).strip(".") or "field"
    if clean.startswith("__"):
        clean = clean.lstrip("_") or "field"
    if clean.lower() in RESERVED_NAMES or clean in taken:
        clean = f"source_{clean}"
    base, k = clean, 1
    while clean in taken:
        k += 1
        clean = f"{base}_{k}"
    return clean


def union_dimensions(readers: list[Reader]) -> list[Dimension]:
    """The store's dimensions: every reader's, in order of first appearance.

    A name met twice must describe the same thing: same kind and LAS record;
    integer dtypes of different width are widened (``numpy.result_type``).
    """
    out: dict[str, Dimension] = {}
    for r in readers:
        for d in r.dimensions:
            old = out.get(d.name)
            if old is None:
                out[d.name] = Dimension(d.name, d.dtype, d.kind, d.description, dict(d.las) if d.las else None)
                continue
            if old.kind != d.kind or _las_key(old) != _las_key(d):
                raise UserError(r.path, f"dimension {d.name!r} differs from the one of an earlier input "
                                        f"({_describe(d)} here, {_describe(old)} before): ingest them separately")
            if old.dtype != d.dtype:
                old.dtype = str(np.result_type(old.dtype, d.dtype))
    return list(out.values())


def _las_key(d: Dimension) -> tuple:
    las = d.las or {}
    return tuple(sorted((k, str(v)) for k, v in las.items() if k not in ("description",)))


def _describe(d: Dimension) -> str:
    return f"{d.kind} {d.dtype}" + (f" {d.las}" if d.las else "")


def fill_value(name: str) -> int:
    """The value of dimension ``name`` for points of a source that lacks it (see :data:`FILL_VALUES`)."""
    return FILL_VALUES.get(name, 0)


def complete_columns(columns: dict[str, np.ndarray], dims: list[Dimension], n: int) -> dict[str, np.ndarray]:
    """Add the store dimensions a part lacks, filled with their "none" value (see :data:`FILL_VALUES`)."""
    out = dict(columns)
    for d in dims:
        if d.name == "point_index" or d.name in out:
            continue
        out[d.name] = np.full(n, fill_value(d.name), dtype=d.dtype)
    return out


def gt_dimension(name: str) -> Dimension:
    """The store's ground-truth dimension ``name`` (``gt_space``, ``gt_class`` or ``gt_instance``)."""
    return next(d for d in gt_dimensions() if d.name == name)


def is_gt_name(name: str) -> bool:
    """True for the name of a ground-truth array."""
    return name in GT_DTYPES


def offset_near(point: np.ndarray | None, step: float = 1000.0) -> tuple[float, float, float]:
    """A round offset near a point (multiples of ``step`` metres, 0 for a cloud near the origin)."""
    if point is None:
        return (0.0, 0.0, 0.0)
    return tuple(float(np.floor(v / step) * step) if abs(v) >= step else 0.0 for v in point)  # type: ignore[return-value]
