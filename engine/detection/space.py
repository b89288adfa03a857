"""Element detection in one space: its frame and integral volume, its windows, their refinement, its proposals.

:func:`detect_space` runs the steps of the paper's section 4 on one space's points: the canonical frame
(:func:`space_frame`), the integral volume and voxel-sorted point index (:func:`prepare_indexed`), the windows
of every class (:mod:`engine.detection.candidates`), the thin-box refinement of surfaces
(:mod:`engine.detection.surfaces`), doors' depth and columns' sides (:mod:`engine.detection.reveal`), the
model's box regression and re-ranking, and the proposals in world coordinates (:func:`to_proposals`).
Design notes: ``docs/design/detection.md``.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from engine.detection import moments as mom
from engine.detection.candidates import class_windows, side_reach, window_candidates
from engine.detection.canonical import CanonicalFrame, estimate_frame
from engine.detection.faces import fit_faces
from engine.detection.footprint import fit_footprints
from engine.detection.model import Model
from engine.detection.openings import fit_openings, one_per_opening
from engine.detection.planar import fit_planar
from engine.detection.pointindex import PointIndex
from engine.detection.proposals import SURE, Proposal
from engine.detection.relief import flat
from engine.detection.reveal import refine_reveals
from engine.detection.settings import DetectionSettings
from engine.detection.sides import settle_sides
from engine.detection.slabs import fit_slabs
from engine.detection.surfaces import refine_surfaces
from engine.detection.tops import fit_tops
from engine.detection.volume import SpaceVolume
from engine.spaces.points import SpacePoints
from tiles.classes import ELEMENT_CLASSES


def space_frame(points: SpacePoints, connection: np.ndarray | None = None, yaw: float | None = None) -> CanonicalFrame:
    """The canonical frame of a space (store-local coordinates), the same at training and run time; ``yaw``: its
    Manhattan orientation given (its group's, :mod:`engine.detection.orientations`) instead of its own."""
    return estimate_frame(points.xyz, connection=connection, yaw=yaw)


def prepare_space(points: SpacePoints, model: Model, frame: CanonicalFrame | None = None) -> SpaceVolume:
    """Frame and integral volume of one space for a model's voxel size."""
    frame = frame if frame is not None else space_frame(points)
    return SpaceVolume.build(points.xyz, points.rgb, frame, model.voxel, model.max_cells, model.layout.colour)


def prepare_indexed(points: SpacePoints, model: Model, frame: CanonicalFrame,
                    with_index: bool = True) -> tuple[SpaceVolume, PointIndex | None]:
    """A space's integral volume and (``with_index``) its voxel-sorted point index, from one pass of
    preparation: canonical points and their voxels, shared by the moments and the index."""
    metric = frame.to_metric(points.xyz)
    grid = mom.VoxelGrid.covering(frame.extent, model.voxel, model.max_cells)
    flat = grid.flat_index(metric)
    vol = SpaceVolume.from_metric(metric, points.rgb, frame, grid, model.layout.colour, flat)
    return vol, (PointIndex(metric, grid, flat) if with_index else None)


@dataclass
class Detections:
    """Detections of one space in its voxel grid, before conversion to proposals."""

    lo: np.ndarray  # (n, 3) voxel box
    hi: np.ndarray
    lo_m: np.ndarray  # (n, 3) refined box, canonical metres
    hi_m: np.ndarray
    score: np.ndarray
    class_code: np.ndarray
    atom: np.ndarray
    sure: np.ndarray | None = None  # (n,) bool: kept whatever its score (a wall at a side, engine.detection.sides)

    @classmethod
    def empty(cls) -> Detections:
        """No detections."""
        z3 = np.zeros((0, 3), dtype=np.int64)
        return cls(z3, z3, z3.astype(float), z3.astype(float), np.zeros(0), np.zeros(0, np.int64),
                   np.zeros(0, np.int64), np.zeros(0, dtype=bool))


def detect_in_volume(vol: SpaceVolume, model: Model, settings: DetectionSettings,
                     index: PointIndex | None = None, classes: list[int] | None = None,
                     candidates: dict[int, tuple[np.ndarray, ...]] | None = None) -> Detections:
    """Sliding windows, NMS and refinement in one prepared space (``candidates``:
    :func:`engine.detection.candidates.window_candidates`'s,
    when already computed)."""
    grid = vol.grid
    candidates = window_candidates(vol, model, settings, classes) if candidates is None else candidates
    per_class = [found for c in (range(len(ELEMENT_CLASSES)) if classes is None else classes)
                 if (found := class_windows(c, candidates, vol, model, settings)) is not None]
    if not per_class:
        return Detections.empty()
    lo, hi, score, cls_all, at_all_cat, candidate = (np.concatenate(parts) for parts in zip(*per_class))
    vox = grid.voxel
    lo_m, hi_m = lo * vox, hi * vox
    at_most = settings.feature_points or None
    sample = None if index is None else partial(index.points_in_metric, at_most=at_most)  # box fit and re-ranking
    if settings.refine and index is not None:
        refine_surfaces(lo, hi, lo_m, hi_m, cls_all, at_all_cat, model.dictionary.atoms_, grid, index, settings)
        refine_reveals(lo, hi, lo_m, hi_m, cls_all, grid, index)  # doors' depth, columns' sides
        if model.boxfit is not None and settings.box_fit:
            model.boxfit.apply(lo_m, hi_m, cls_all, sample, np.asarray(vol.frame.extent, float))
    if settings.refine and index is not None and model.rescorer is not None and settings.rescore:
        score = model.rescorer.apply(score, cls_all, lo_m, hi_m, sample,
                                     np.asarray(vol.frame.extent, float), settings.rescore_clip)
    if settings.cut:  # the kept set's cut per class: a positive score still means kept
        score = score - settings.cut_array()[cls_all]
    keep, sure = side_walls(lo, hi, score, cls_all, candidate, grid, settings)
    lo, hi, lo_m, hi_m, score, cls_all, at_all_cat, sure = kept(keep, lo, hi, lo_m, hi_m, score, cls_all, at_all_cat, sure)
    if settings.refine and index is not None and settings.planar_classes:
        # the depth of boards on walls from their points, after the scores (engine/detection/planar.py)
        fit_planar(lo_m, hi_m, cls_all, index.points_in_metric, settings.planar_classes, settings.planar_depth,
                   settings.planar_beside, settings.planar_quantile, np.asarray(vol.frame.extent, float))
    if settings.refine and index is not None and settings.face_classes:  # boards as wide and tall as their face
        _, bare = fit_faces(lo_m, hi_m, cls_all, index.points_in_metric, settings.face_classes, settings.face_grow,
                            np.asarray(vol.frame.extent, float))
        lo, hi, lo_m, hi_m, score, cls_all, at_all_cat, sure = kept(~bare, lo, hi, lo_m, hi_m, score, cls_all, at_all_cat,
                                                                    sure)  # nothing stands out of the wall there
    if settings.refine and index is not None and settings.opening_classes:  # windows as their openings
        followed, sill = fit_openings(lo_m, hi_m, cls_all, index.points_in_metric, settings.opening_classes,
                                      settings.opening_grow, np.asarray(vol.frame.extent, float))
        score = score + settings.opening_bonus * sill  # a window's opening in the wall: its evidence
        keep = one_per_opening(lo_m, hi_m, score, followed, settings.nms_iou)  # a ribbon's pieces make one
        lo, hi, lo_m, hi_m, score, cls_all, at_all_cat, sure = kept(keep, lo, hi, lo_m, hi_m, score, cls_all, at_all_cat,
                                                                    sure)
    if settings.refine and index is not None and settings.top_classes:  # bookcases as tall as their points
        fit_tops(lo_m, hi_m, cls_all, index.points_in_metric, settings.top_classes, settings.top_reach,
                 np.asarray(vol.frame.extent, float))
    if settings.refine and index is not None and settings.slab_classes:  # floors as wide as their own points
        fit_slabs(lo_m, hi_m, cls_all, index.points_in_metric, settings.slab_classes, settings.slab_fraction)
    if settings.refine and index is not None and settings.footprint_classes:  # chairs as wide as their points
        fit_footprints(lo_m, hi_m, cls_all, index.points_in_metric, settings.footprint_classes,
                       settings.footprint_grow, np.asarray(vol.frame.extent, float))
    if settings.hanging_classes:  # a beam hangs from the ceiling: not one whose top is in the lower half
        keep = ~fallen(cls_all, hi_m, float(vol.frame.extent[2]), settings.hanging_classes)
        lo, hi, lo_m, hi_m, score, cls_all, at_all_cat, sure = kept(keep, lo, hi, lo_m, hi_m, score, cls_all, at_all_cat,
                                                                    sure)
    if settings.relief_classes and index is not None:  # a beam stands out from the ceiling beside and below it
        keep = ~flat(cls_all, lo_m, hi_m, index.points_in_metric, settings.relief_classes, settings.relief_ratio,
                     settings.relief_gap)
        lo, hi, lo_m, hi_m, score, cls_all, at_all_cat, sure = kept(keep, lo, hi, lo_m, hi_m, score, cls_all, at_all_cat,
                                                                    sure)
    return Detections(lo, hi, lo_m, hi_m, score, cls_all, at_all_cat, sure)


def kept(keep: np.ndarray, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """``arrays`` (one row per detection) cut to the rows ``keep``: the same arrays when every row is kept."""
    return arrays if keep.all() else tuple(a[keep] for a in arrays)


def side_walls(lo: np.ndarray, hi: np.ndarray, score: np.ndarray, class_code: np.ndarray, candidate: np.ndarray,
               grid: mom.VoxelGrid, settings: DetectionSettings) -> tuple[np.ndarray, np.ndarray]:
    """``(keep, sure)``: :func:`engine.detection.sides.settle_sides` for each class of ``side-classes``."""
    keep, sure = np.ones(len(score), dtype=bool), np.zeros(len(score), dtype=bool)
    for name in settings.side_classes:
        of = np.asarray(class_code) == ELEMENT_CLASSES.index(name)
        if of.any():
            k, s = settle_sides(lo, hi, score, of, candidate, grid.shape, settings.thin_voxels,
                                side_reach(settings, grid.voxel))
            keep &= k
            sure |= s
    return keep, sure


def fallen(class_code: np.ndarray, hi_m: np.ndarray, height: float, hanging: tuple[str, ...]) -> np.ndarray:
    """Which detections of the classes ``hanging`` (that hang from the ceiling) have their top (``hi_m[:, 2]``,
    canonical metres from the space's floor) in the lower half of a space ``height`` metres high."""
    codes = [ELEMENT_CLASSES.index(c) for c in hanging]
    return np.isin(np.asarray(class_code), codes) & (np.asarray(hi_m)[:, 2] < 0.5 * height)


def to_proposals(det: Detections, vol: SpaceVolume, model: Model, space_id: int,
                 origin: np.ndarray) -> list[Proposal]:
    """Detections as :class:`Proposal` objects in world coordinates (``origin`` = store-local to world shift)."""
    f = vol.frame
    world = CanonicalFrame(f.yaw, f.origin + np.asarray(origin, dtype=np.float64), f.extent, f.entrance, f.info)
    out = []
    atoms = model.dictionary.atoms_
    sure = np.zeros(len(det.score), dtype=bool) if det.sure is None else det.sure
    for i in range(len(det.score)):
        p = det.lo_m[i] / f.extent
        s = (det.hi_m[i] - det.lo_m[i]) / f.extent
        center, size, yaw = world.unit_box_to_world(p, s)
        out.append(Proposal(space_id=int(space_id), class_code=int(det.class_code[i]), score=float(det.score[i]),
                            position=p, size=s, occupancy=atoms[int(det.atom[i])].occupancy.copy(),
                            center=center, world_size=size, yaw=float(yaw),
                            extra={"atom": int(det.atom[i]), **({SURE: True} if sure[i] else {})}))
    return out


def detect_space(points: SpacePoints, model: Model, settings: DetectionSettings | None = None,
                 origin: np.ndarray | None = None, connection: np.ndarray | None = None,
                 yaw: float | None = None) -> list[Proposal]:
    """All proposals of one space (its points in store-local coordinates), in a frame of ``yaw`` (its own: None)."""
    settings = settings or DetectionSettings.from_config()
    if len(points.xyz) < max(settings.min_window_points, 4):
        return []
    vol, index = prepare_indexed(points, model, space_frame(points, connection, yaw), settings.refine)
    det = detect_in_volume(vol, model, settings, index)
    return to_proposals(det, vol, model, points.space_id, np.zeros(3) if origin is None else origin)
