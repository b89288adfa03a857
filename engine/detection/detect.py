"""Element detection as a pipeline stage: sliding windows per space, as dask tasks (paper section 4).

:func:`detect` runs :func:`engine.detection.space.detect_space` on every space of a store, one task each (its
points gathered from the tiles it touches), the largest spaces first, and numbers the proposals.  First every
space's own yaw, one task each, so that each space is detected in its group's orientation
(:mod:`engine.detection.orientations`).
The steps in a space and the reasons for them: ``docs/design/detection.md``.
Settings: ``buildingparser.detection.*`` (``engine/detection/detection.yaml``).
"""
from __future__ import annotations

import logging

import numpy as np

from engine.detection.canonical import manhattan_yaw
from engine.detection.model import Model, load_model
from engine.detection.orientations import reference_yaws, wrap_quarter
from engine.detection.proposals import Proposal
from engine.detection.settings import DetectionSettings
from engine.detection.space import detect_space
from engine.detection.sparse import sparse_spaces
from engine.spaces.points import SpaceRef, index_spaces, load_space
from tiles.tasks import run_tasks

logger = logging.getLogger(__name__)


def connection_hints(store, space_array: str = "space_id") -> dict[int, np.ndarray]:
    """Per parsed space, the store-local plan position of its longest shared face (``meta/spaces``).

    Only for ``space_id`` spaces of a store that has the document; the canonical
    frame uses it when no wall shows a door-like opening.
    """
    doc = store.doc("spaces") if space_array == "space_id" else None
    out: dict[int, np.ndarray] = {}
    if not doc:
        return out
    origin = np.asarray(store.meta.origin[:2], dtype=np.float64)
    for sp in doc.get("spaces", []):
        best, where = 0.0, None
        for nb in sp.get("neighbours", []):
            for face in nb.get("faces", []):
                seg = np.asarray(face.get("segment", []), dtype=np.float64)
                if seg.shape != (2, 2):
                    continue
                length = float(np.hypot(*(seg[1] - seg[0])))
                if length > best:
                    best, where = length, seg.mean(axis=0) - origin
        if where is not None:
            out[int(sp["id"])] = where
    return out


def by_size(refs: list[SpaceRef]) -> list[SpaceRef]:
    """Spaces in the order their tasks should start: most points first (ties by id), the longest tasks first."""
    return sorted(refs, key=lambda r: (-r.count, r.space_id))


def without_sparse(refs: list[SpaceRef], doc: dict | None, ratio: float) -> list[SpaceRef]:
    """``refs`` without the spaces too sparse to be scanned rooms (:mod:`engine.detection.sparse`), logged."""
    sparse = sparse_spaces(doc, ratio)
    if not sparse:
        return refs
    kept = [r for r in refs if r.space_id not in sparse]
    skipped = [r for r in refs if r.space_id in sparse]
    logger.info("detection: %d of %d spaces (%d points) hold under %g of the typical space's points per m2 of "
                "floor: too sparse to be scanned rooms, no elements detected in them", len(skipped), len(refs),
                sum(r.count for r in skipped), ratio)
    return kept


def _yaw_task(ref: SpaceRef, store, space_array: str, min_points: int) -> float:
    xyz = load_space(store, ref, space_array, colour=False).xyz  # the yaw needs no colour
    return manhattan_yaw(xyz) if len(xyz) >= min_points else float("nan")  # too few points to detect in


def _detect_task(job: tuple[SpaceRef, np.ndarray | None, float | None], store, model: Model, space_array: str,
                 settings: DetectionSettings) -> list[Proposal]:
    ref, hint, yaw = job
    points = load_space(store, ref, space_array)
    return detect_space(points, model, settings, np.asarray(store.meta.origin, dtype=np.float64), hint, yaw)


def space_yaws(store, refs: list[SpaceRef], client=None, space_array: str = "space_id",
               tolerance_deg: float = 1.0, min_points: int = 4) -> list[float | None]:
    """The yaw each space of ``refs`` is detected in (:mod:`engine.detection.orientations`): its group's, from
    every space's own (one task per space); all None (each its own) when ``tolerance_deg`` is 0, None for a space
    under ``min_points`` points (no detection there: no say in its group's yaw)."""
    if tolerance_deg <= 0 or not refs:
        return [None] * len(refs)
    own = np.array(run_tasks(_yaw_task, refs, client=client, label="space orientations",
                             keys=[f"yaw of space {r.space_id}" for r in refs],
                             extra_args=(store, space_array, min_points)), dtype=np.float64)
    ref = reference_yaws(own, np.radians(tolerance_deg))
    turned = np.degrees(np.abs(wrap_quarter(own - ref)))[np.isfinite(own)]
    if len(turned):
        logger.info("detection: %d of %d spaces detected in their group's orientation (turned by %.2f degrees at "
                    "most, median %.2f)", int(np.count_nonzero(turned > 0)), len(refs), float(turned.max()),
                    float(np.median(turned)))
    return [float(y) if np.isfinite(y) else None for y in ref]


def detect(store, *, model: Model | str | None = None, client=None, space_array: str = "space_id",
           settings: DetectionSettings | None = None) -> list[Proposal]:
    """Element proposals of every space of a store, one dask task per space.

    Parameters
    ----------
    store
        A :class:`tiles.store.TileStore` with per-point ``space_array`` ids.
    model
        A :class:`Model`, a model path, or None for the shipped default model.
    client
        A ``distributed.Client``; None runs here.
    space_array
        ``"space_id"`` (parsed spaces) or ``"gt_space"`` (ground-truth spaces).
    settings
        Detection settings; default from ``buildingparser.detection.*``.

    Returns
    -------
    The proposals of all spaces (world coordinates), with ``element_id`` numbered
    from 0 by space, class and decreasing score.
    """
    if not isinstance(model, Model):
        model = load_model(model)
    settings = settings or DetectionSettings.from_config()
    refs = index_spaces(store, space_array, client=client)
    if space_array == "space_id":
        refs = without_sparse(refs, store.doc("spaces"), settings.min_space_density)
    hints = connection_hints(store, space_array)
    if client is not None and refs:
        [model_arg] = client.scatter([model], broadcast=True)
    else:
        model_arg = model
    # largest spaces first: dask starts tasks in submission order, so the long ones do not end the stage with
    # one worker idle (a space's task time grows with its points; the medium bench_run building, 15 spaces on
    # 2 workers: the largest space, 20 % of the stage's task seconds, came ninth by id and ran alone at the end)
    refs = by_size(refs)
    yaws = space_yaws(store, refs, client, space_array, settings.orientation_tolerance,
                      max(settings.min_window_points, 4))
    results = run_tasks(_detect_task, [(r, hints.get(r.space_id), y) for r, y in zip(refs, yaws)], client=client,
                        label="detect elements",
                        keys=[f"space {r.space_id}" for r in refs],
                        extra_args=(store, model_arg, space_array, settings))
    # by space, class and score as before; the sort is stable, so ties keep their order within a space
    proposals = [p for r in results for p in r]
    proposals.sort(key=lambda p: (p.space_id, p.class_code, -p.score))
    for i, p in enumerate(proposals):
        p.element_id = i
    return proposals
