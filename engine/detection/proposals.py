"""Detections as they flow from the sliding-window detector through the CRF to ``elements.json``.

A :class:`Proposal` lives in two frames: the canonical unit cube of its space
(position ``P`` = min corner, size ``S``, occupancy pattern ``B`` on the
K x K x K sub-boxes: what the CRF's edge features use) and the world (centre,
size along the box's own axes, yaw about z: what is written out and scored).

``elements.json`` (in ``run``'s output folder) is a JSON list of
:meth:`Proposal.element_record` dicts::

    {"element_id", "class", "class_code", "score", "space_id",
     "center": [x, y, z], "size": [dx, dy, dz], "yaw", "voxels": [[cx, cy, cz, dx, dy, dz], ...]}

``voxels`` are the occupied sub-boxes (centre and size in the box's own axes,
relative to ``center``) and may be absent.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tiles.classes import CLASS_NAMES

#: Key of :attr:`Proposal.extra` marking a proposal kept whatever its score: a wall added at a side of its space
#: (:mod:`engine.detection.sides`); the CRF keeps it, the space update does not read it as evidence of a wall.
SURE = "sure"


@dataclass
class Proposal:
    space_id: int
    class_code: int
    score: float
    position: np.ndarray  # (3,) P, min corner in the space's unit cube
    size: np.ndarray  # (3,) S, size in the unit cube
    occupancy: np.ndarray  # (K, K, K) bool, B
    center: np.ndarray  # (3,) world
    world_size: np.ndarray  # (3,) metres along the box's own axes
    yaw: float  # radians about z, world
    element_id: int = -1
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def class_name(self) -> str:
        return CLASS_NAMES[self.class_code]

    def element_record(self, with_voxels: bool = True) -> dict[str, Any]:
        """The ``elements.json`` record of this detection."""
        rec: dict[str, Any] = {
            "element_id": int(self.element_id), "class": self.class_name, "class_code": int(self.class_code),
            "score": float(self.score), "space_id": int(self.space_id),
            "center": [float(v) for v in self.center], "size": [float(v) for v in self.world_size],
            "yaw": float(self.yaw),
        }
        if with_voxels:
            rec["voxels"] = occupied_voxels(self.occupancy, self.world_size)
        return rec


def occupied_voxels(occupancy: np.ndarray, size: np.ndarray) -> list[list[float]]:
    """Centres and sizes of the occupied sub-boxes, in the box's own axes relative to its centre."""
    occ = np.asarray(occupancy, dtype=bool)
    k = np.array(occ.shape, dtype=float)
    step = np.asarray(size, dtype=float) / k
    idx = np.argwhere(occ)
    centres = (idx + 0.5) * step - np.asarray(size, dtype=float) / 2
    return [[*map(float, c), *map(float, step)] for c in centres]


def proposal_to_json(p: Proposal) -> dict[str, Any]:
    """A lossless JSON form of a proposal (what a resumed run reads back from the store)."""
    occ = np.asarray(p.occupancy, dtype=bool)
    return {"space_id": int(p.space_id), "class_code": int(p.class_code), "score": float(p.score),
            "position": [float(v) for v in p.position], "size": [float(v) for v in p.size],
            "occupancy_shape": list(occ.shape), "occupancy": np.flatnonzero(occ.ravel()).tolist(),
            "center": [float(v) for v in p.center], "world_size": [float(v) for v in p.world_size],
            "yaw": float(p.yaw), "element_id": int(p.element_id), "extra": _plain(p.extra)}


def proposal_from_json(d: dict[str, Any]) -> Proposal:
    occ = np.zeros(int(np.prod(d["occupancy_shape"])), dtype=bool)
    occ[np.asarray(d["occupancy"], dtype=np.int64)] = True
    return Proposal(space_id=int(d["space_id"]), class_code=int(d["class_code"]), score=float(d["score"]),
                    position=np.asarray(d["position"], dtype=np.float64), size=np.asarray(d["size"], dtype=np.float64),
                    occupancy=occ.reshape(d["occupancy_shape"]), center=np.asarray(d["center"], dtype=np.float64),
                    world_size=np.asarray(d["world_size"], dtype=np.float64), yaw=float(d["yaw"]),
                    element_id=int(d.get("element_id", -1)), extra=dict(d.get("extra", {})))


def _plain(x: Any) -> Any:
    """JSON-able copy of small extra data (numpy scalars and arrays become Python values)."""
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    return x
