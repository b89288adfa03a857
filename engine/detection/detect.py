"""Element detection as a pipeline stage: sliding windows per space, as dask tasks (paper section 4).

For every space (one task each, its points gathered from the tiles it touches):

1. its canonical frame from its own points (:func:`engine.detection.canonical.estimate_frame`);
2. one pass over its points: voxel moments and their integral volume
   (:class:`engine.detection.features.SpaceVolume`, voxel size and K from the model);
3. for every class, every window of the dictionary slid over the unit cube and
   scored by the class's linear SVM (:func:`engine.detection.sliding.score_windows_many`: the atoms
   of one voxel shape in the space are scored together, their features computed once);
   windows above ``score-threshold``, the ``pre-nms`` best per window shape;
4. per class, non-maximum suppression (3D IoU ``nms-iou`` of the boxes grown
   to at least ``nms-min-size`` metres, so that parallel slivers of one surface
   suppress each other), at most ``max-per-class`` proposals, and only the best
   one of the classes a space has exactly one of (``one-per-space``: its floor
   and its ceiling);
5. thin-box refinement of the surface classes (``refine-classes``: walls,
   floors, ceilings; a door or a window is a box as deep as its reveal, not a
   surface): along an axis where a detection is at most
   ``thin-voxels`` voxels thick and its window's learned size is under half a
   voxel (surfaces seen from one side: walls, floors, ceilings), its extent
   becomes the dense run (bins holding at least 2 % of the peak) around the peak
   of its points' histogram along that axis (``refine-bin`` metres), so that a
   3 cm wall is not reported as a 10 cm voxel slab.  First the box moves to
   the surface (:func:`surface_shift`): when the peak of the histogram of the box
   grown along that axis as NMS grew it (to ``nms-min-size``) lies outside the
   box and is at least twice as dense as any bin inside it (a plane), the box
   moves by whole voxels to hold it.  The windows NMS merged into
   this detection lie there, and the best-scoring one may be the layer beside
   the surface: under a ceiling crossed by beams, the layer of the beams' sides,
   the ceiling one voxel above.  The points are found through a voxel-sorted
   index, not a search;
6. the model's learned box regression, if it has one (:mod:`engine.detection.boxfit`, ``box-fit``):
   the classes it was validated for have their faces moved by it;
7. the model's learned re-ranking, if it has one (:mod:`engine.detection.rescore`, ``rescore``): the
   classes it was validated for take its log-odds, from the points around their final boxes,
   as their score;
8. the proposals, mapped back to world coordinates through the frame
   (:class:`engine.detection.proposals.Proposal`: unit-cube P, S, B plus the world box).

Settings: ``buildingparser.detection.*`` (``engine/detection/detection.yaml``).
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from engine import config
from engine.detection import moments as mom
from engine.detection.canonical import CanonicalFrame, estimate_frame
from engine.detection.features import SpaceVolume, window_features
from engine.detection.model import Model, load_model
from engine.detection.proposals import Proposal
from engine.detection.reveal import refine_reveals
from engine.detection.sliding import WindowScores, non_maximum_suppression, score_windows_many, window_shape
from engine.spaces.points import SpacePoints, SpaceRef, index_spaces, load_space
from tiles.classes import ELEMENT_CLASSES, element_class_list
from tiles.tasks import run_tasks

CEILING, FLOOR = ELEMENT_CLASSES.index("ceiling"), ELEMENT_CLASSES.index("floor")
#: How a space's one ceiling and floor are chosen among their windows (:func:`surface_order`).
SURFACE_CHOICES = ("extreme", "halves", "score")


@dataclass
class DetectionSettings:
    """Run-time settings of the detector (see ``engine/detection/detection.yaml``)."""

    stride: float = 0.25
    max_stride: float = 0.2
    min_window_points: int = 10
    score_threshold: float = -0.75
    pre_nms: int = 300
    nms_iou: float = 0.3
    nms_min_size: float = 0.3
    max_per_class: int = 30
    one_per_space: tuple[str, ...] = ("ceiling", "floor")
    surface_choice: str = "extreme"
    local_search: bool = True
    refine: bool = True
    refine_classes: tuple[str, ...] = ("ceiling", "floor", "wall")
    thin_voxels: int = 2
    refine_bin: float = 0.005
    label_margin: float = 0.02
    box_fit: bool = True
    rescore: bool = True

    def __post_init__(self) -> None:
        if not 0 < self.stride <= 1:
            raise ValueError(f"stride must be in (0, 1], got {self.stride}")
        if self.max_stride <= 0:
            raise ValueError(f"max-stride must be positive, got {self.max_stride}")
        if not 0 <= self.nms_iou <= 1:
            raise ValueError(f"nms-iou must be in [0, 1], got {self.nms_iou}")
        if self.max_per_class < 1 or self.pre_nms < 1:
            raise ValueError("max-per-class and pre-nms must be >= 1")
        if self.surface_choice not in SURFACE_CHOICES:
            raise ValueError(f"surface-choice must be one of {', '.join(SURFACE_CHOICES)}, got {self.surface_choice!r}")
        if self.refine_bin <= 0 or self.thin_voxels < 0 or self.label_margin < 0:
            raise ValueError("refine-bin must be > 0, thin-voxels and label-margin >= 0")
        for name in ("one_per_space", "refine_classes"):
            setattr(self, name, element_class_list(getattr(self, name), name.replace("_", "-")))

    @classmethod
    def from_config(cls, **overrides: Any) -> DetectionSettings:
        """Settings from ``buildingparser.detection.*``, with keyword overrides."""
        kw = config.settings_fields(cls, "detection")
        kw.update(overrides)
        return cls(**kw)

    def to_json(self) -> dict[str, Any]:
        return {f.name: (list(v) if isinstance(v := getattr(self, f.name), tuple) else v) for f in fields(self)}


class PointIndex:
    """A space's canonical points sorted by voxel, so that the points of a voxel box are a few slices.

    (Sorted once, by :func:`engine.detection.moments.voxel_order`: the refined boxes are
    few but large, floors and ceilings holding a third of the points each, and
    gathering them through the order box by box costs more than one sort.)
    """

    def __init__(self, metric: np.ndarray, grid: mom.VoxelGrid, flat: np.ndarray | None = None):
        self.grid = grid
        flat = grid.flat_index(metric) if flat is None else flat
        n_cells = int(np.prod(grid.shape))
        self.points = metric[mom.voxel_order(flat, n_cells)]
        self.offsets = np.concatenate([[0], np.cumsum(np.bincount(flat, minlength=n_cells))])

    def points_in_metric(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Canonical points of the voxels that the metric box ``[lo, hi]`` touches (a superset of its points)."""
        vox = np.asarray(self.grid.voxel, dtype=np.float64)
        n = np.asarray(self.grid.shape)
        vlo = np.clip(np.floor(np.asarray(lo) / vox).astype(np.int64), 0, n - 1)
        vhi = np.clip(np.ceil(np.asarray(hi) / vox).astype(np.int64), vlo + 1, n)
        return self.points_in(vlo, vhi)

    def points_in(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Canonical points ``(m, 3)`` of the voxel box ``[lo, hi)``."""
        nx, ny, nz = self.grid.shape
        xs, ys = np.meshgrid(np.arange(lo[0], hi[0]), np.arange(lo[1], hi[1]), indexing="ij")
        col = (xs.ravel() * ny + ys.ravel()) * nz
        start, stop = self.offsets[col + lo[2]], self.offsets[col + hi[2]]
        lengths = stop - start
        total = int(lengths.sum())
        if total == 0:
            return np.zeros((0, 3))
        base = np.repeat(start - np.concatenate([[0], np.cumsum(lengths)[:-1]]), lengths)
        return self.points[base + np.arange(total)]


def refine_extent(values: np.ndarray, lo: float, hi: float, bin_size: float, frac: float = 0.02,
                  sigmas: float = 3.0) -> tuple[float, float]:
    """The extent of the surface in ``values`` around the peak of their histogram in ``[lo, hi]``.

    First the dense run of the histogram (``bin_size`` bins holding at least ``frac``
    of the peak) around its peak; then, within it, the band ``median +- sigmas``
    robust standard deviations (1.4826 MAD) of its values: the band that holds the
    surface's points under Gaussian scan noise (99.7 % at 3 sigma), without the few
    stray points of things touching the surface that widen the dense run.  The band
    is at least one bin wide.
    """
    if len(values) == 0:
        return lo, hi
    nb = max(int(np.ceil((hi - lo) / bin_size)), 1)
    h = np.bincount(np.clip(((values - lo) / bin_size).astype(np.int64), 0, nb - 1), minlength=nb)
    peak = int(np.argmax(h))
    dense = h >= frac * h[peak]
    a = peak
    while a > 0 and dense[a - 1]:
        a -= 1
    b = peak
    while b < nb - 1 and dense[b + 1]:
        b += 1
    run_lo, run_hi = lo + a * bin_size, min(lo + (b + 1) * bin_size, hi)
    v = values[(values >= run_lo) & (values <= run_hi)]
    if len(v) < 3:
        return run_lo, run_hi
    med = float(np.median(v))
    half = max(sigmas * 1.4826 * float(np.median(np.abs(v - med))), bin_size / 2)
    return max(run_lo, med - half), min(run_hi, med + half)


def surface_shift(values: np.ndarray, lo: int, hi: int, search_lo: int, search_hi: int, voxel: float,
                  bin_size: float, min_gain: float = 2.0) -> int:
    """Voxels to move a thin box ``[lo, hi)`` along one axis so that it holds the surface beside it.

    ``values`` are the coordinates (metres) along that axis of the points in
    ``[search_lo, search_hi)`` voxels.  The surface is the peak of their histogram
    (``bin_size`` metres) when it lies outside ``[lo, hi)`` and holds at least
    ``min_gain`` times the points of the densest bin inside it (a plane, not the
    random top of evenly spread points); the box then makes the smallest move that
    brings the peak's voxel into it.  Otherwise (and without points) 0.
    """
    if len(values) == 0:
        return 0
    a, b = search_lo * voxel, search_hi * voxel
    nb = max(int(np.ceil((b - a) / bin_size)), 1)
    h = np.bincount(np.clip(((values - a) / bin_size).astype(np.int64), 0, nb - 1), minlength=nb)
    centres = a + (np.arange(nb) + 0.5) * bin_size
    layer = np.clip(np.floor(centres / voxel).astype(np.int64), search_lo, search_hi - 1)
    inside = (layer >= lo) & (layer < hi)
    peak = int(np.argmax(h))
    if inside[peak] or h[peak] < min_gain * h[inside].max(initial=0):
        return 0
    return int(layer[peak] - (hi - 1) if layer[peak] >= hi else layer[peak] - lo)


def space_frame(points: SpacePoints, connection: np.ndarray | None = None) -> CanonicalFrame:
    """The canonical frame of a space (store-local coordinates), the same at training and run time."""
    return estimate_frame(points.xyz, connection=connection)


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


def local_search(vol: SpaceVolume, lo: np.ndarray, hi: np.ndarray, scores: np.ndarray, weights: np.ndarray,
                 bias: np.ndarray | float, layout, stride: float, max_stride: float | None) -> tuple[np.ndarray,
                                                                                                  np.ndarray,
                                                                                                  np.ndarray]:
    """Move each detection by half a sliding step along each axis (27 candidates) to its best score.

    ``weights`` is ``(D,)`` for all detections or ``(n, D)`` one row per detection (its window's,
    :meth:`engine.detection.model.Model.window_weights`), ``bias`` a scalar or ``(n,)``.

    The coarse grid places a window up to half a step off; its score is highest
    where it fits, so the best of the half-step neighbours is kept (the window's
    size is unchanged).  Cheap: only the few windows that survived NMS are moved.
    """
    if not len(lo):
        return lo, hi, scores
    n = np.asarray(vol.grid.shape)
    w = hi - lo
    step = np.maximum(1, np.round(w * stride)).astype(np.int64)
    if max_stride is not None:
        step = np.minimum(step, np.maximum(1, np.floor(max_stride / vol.grid.voxel + 1e-9)).astype(np.int64))
    half = np.where(w < n, np.maximum(step // 2, 1), 0)  # spanning axes do not move
    offs = np.stack(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1], indexing="ij"), axis=-1).reshape(-1, 3)
    cand_lo = lo[:, None, :] + offs[None] * half[:, None, :]
    cand_lo = np.clip(cand_lo, 0, n - w[:, None, :])
    cand_hi = cand_lo + w[:, None, :]
    flat_lo, flat_hi = cand_lo.reshape(-1, 3), cand_hi.reshape(-1, 3)
    feats = window_features(vol.iv, vol.grid, flat_lo, flat_hi, layout)
    w_rows = np.broadcast_to(np.where(layout.mask, weights, 0.0), (len(lo), layout.size))
    b_rows = np.broadcast_to(np.asarray(bias, dtype=np.float64), (len(lo),))
    cand = np.einsum("ncd,nd->nc", feats.reshape(len(lo), len(offs), -1), w_rows) + b_rows[:, None]
    best = np.argmax(cand, axis=1)
    idx = np.arange(len(lo))
    better = cand[idx, best] > scores
    new_lo = np.where(better[:, None], cand_lo[idx, best], lo)
    return new_lo, new_lo + w, np.where(better, cand[idx, best], scores)


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


def window_candidates(vol: SpaceVolume, model: Model, settings: DetectionSettings,
                      classes: list[int] | None = None) -> dict[int, tuple[np.ndarray, ...]]:
    """Per dictionary atom, its windows above ``score-threshold`` (at most ``pre-nms``, best first).

    Returns ``{atom index: (lo, hi, score, atom index per window)}`` for the atoms of the
    trained (and requested) classes that have any.  Atoms whose windows have the same
    voxel shape in this space are scored together (:func:`engine.detection.sliding.score_windows_many`
    computes their features once): the scores are those of one :func:`engine.detection.sliding.score_windows` call each.
    """
    grid = vol.grid
    wanted = set(range(len(ELEMENT_CLASSES)) if classes is None else classes)
    groups: dict[tuple[int, ...], list[int]] = {}
    for ai, atom in enumerate(model.dictionary.atoms_):
        c = atom.class_code
        if c in wanted and model.trained[c]:
            shape = window_shape(atom.size_in(grid.extent), grid)
            groups.setdefault(tuple(int(v) for v in shape), []).append(ai)
    out: dict[int, tuple[np.ndarray, ...]] = {}
    for shape, members in groups.items():
        w, b = model.window_weights(members)
        scored = score_windows_many(vol, np.array(shape), w, b, model.layout, settings.stride,
                                    settings.min_window_points, settings.max_stride)
        for ai, ws in zip(members, scored):
            top = top_windows(ws, ai, settings)
            if top is not None:
                out[ai] = top
    return out


def top_windows(ws: WindowScores, atom: int, settings: DetectionSettings) -> tuple[np.ndarray, ...] | None:
    """One window shape's scored positions above ``score-threshold``, at most ``pre-nms`` of the best.

    Returns ``(lo, hi, score, atom index per window)``, or None when no window passes.
    """
    flat = ws.scores.ravel()
    ok = np.nonzero(flat > settings.score_threshold)[0]
    if len(ok) > settings.pre_nms:
        ok = ok[np.argpartition(-flat[ok], settings.pre_nms - 1)[:settings.pre_nms]]
    if not len(ok):
        return None
    lo, hi = ws.boxes(ok)
    return lo, hi, flat[ok], np.full(len(ok), atom)


def detect_in_volume(vol: SpaceVolume, model: Model, settings: DetectionSettings,
                     index: PointIndex | None = None, classes: list[int] | None = None,
                     candidates: dict[int, tuple[np.ndarray, ...]] | None = None) -> Detections:
    """Sliding windows, NMS and refinement in one prepared space (``candidates``: :func:`window_candidates`'s,
    when already computed)."""
    grid = vol.grid
    lo_all, hi_all, sc_all, cl_all, at_all = [], [], [], [], []
    atoms = model.dictionary.atoms_
    candidates = window_candidates(vol, model, settings, classes) if candidates is None else candidates
    for c in (range(len(ELEMENT_CLASSES)) if classes is None else classes):
        found = [candidates[ai] for ai in sorted(candidates) if atoms[ai].class_code == c]
        if not found:
            continue
        los, his, scs, ats = zip(*found)
        lo, hi, sc, at = np.concatenate(los), np.concatenate(his), np.concatenate(scs), np.concatenate(ats)
        # NMS on boxes grown to nms-min-size: parallel slivers of one surface suppress each other
        pad = np.clip(np.ceil(settings.nms_min_size / grid.voxel) - (hi - lo), 0, None) / 2.0
        keep = non_maximum_suppression(lo - pad, hi + pad, sc, settings.nms_iou, settings.max_per_class)
        if settings.local_search:
            lo, hi, sc = lo[keep], hi[keep], sc[keep]
            at = at[keep]
            w, b = model.window_weights(at)
            lo, hi, sc = local_search(vol, lo, hi, sc, w, b, model.layout, settings.stride, settings.max_stride)
            pad = np.clip(np.ceil(settings.nms_min_size / grid.voxel) - (hi - lo), 0, None) / 2.0
            keep = non_maximum_suppression(lo - pad, hi + pad, sc, settings.nms_iou, settings.max_per_class)
        if ELEMENT_CLASSES[c] in settings.one_per_space:
            if ELEMENT_CLASSES[c] in ("ceiling", "floor"):
                keep = surface_order(keep, lo, hi, grid.shape[2], ELEMENT_CLASSES[c] == "ceiling",
                                     settings.surface_choice)
            keep = keep[:1]  # a space has one floor and one ceiling: the first window of the class
        lo_all.append(lo[keep]), hi_all.append(hi[keep]), sc_all.append(sc[keep])
        cl_all.append(np.full(len(keep), c)), at_all.append(at[keep])
    if not lo_all:
        z3 = np.zeros((0, 3), dtype=np.int64)
        return Detections(z3, z3, z3.astype(float), z3.astype(float), np.zeros(0), np.zeros(0, np.int64),
                          np.zeros(0, np.int64))
    lo, hi = np.concatenate(lo_all), np.concatenate(hi_all)
    at_all_cat = np.concatenate(at_all)
    vox = grid.voxel
    lo_m, hi_m = lo * vox, hi * vox
    cls_all = np.concatenate(cl_all)
    if settings.refine and index is not None:
        n = np.asarray(grid.shape)
        surface = np.isin(cls_all, [ELEMENT_CLASSES.index(c) for c in settings.refine_classes])
        for i in np.nonzero(surface)[0]:
            # surfaces thinner than half a voxel (walls, floors, ceilings as seen from inside)
            atom = atoms[int(at_all_cat[i])]
            need = np.minimum(atom.size_in(grid.extent), atom.metric_size)
            thin = np.nonzero((hi[i] - lo[i] <= settings.thin_voxels) & (need < 0.5 * vox))[0]
            for a in thin:
                # the surface is looked for in the box grown along this axis as NMS grew it: the
                # windows NMS merged into this one lie there, and the best-scoring layer may be the
                # one beside the surface (under a ceiling crossed by beams: the beams' sides)
                pad = int(max(np.ceil(settings.nms_min_size / vox[a]) - (hi[i, a] - lo[i, a]), 0) // 2)
                # a space's one ceiling (floor) is its highest (lowest) dense surface: looked for up to the
                # top (down to the bottom) of the space, above beams' undersides or a lowered part
                up = a == 2 and settings.surface_choice == "extreme" and cls_all[i] == CEILING
                down = a == 2 and settings.surface_choice == "extreme" and cls_all[i] == FLOOR
                if pad or up or down:
                    blo, bhi = lo[i].copy(), hi[i].copy()
                    blo[a], bhi[a] = max(lo[i, a] - pad, 0), min(hi[i, a] + pad, n[a])
                    bhi[a] = n[a] if up else bhi[a]
                    blo[a] = 0 if down else blo[a]
                    shift = surface_shift(index.points_in(blo, bhi)[:, a], int(lo[i, a]), int(hi[i, a]),
                                          int(blo[a]), int(bhi[a]), vox[a], settings.refine_bin)
                    lo[i, a] += shift
                    hi[i, a] += shift
                    lo_m[i, a], hi_m[i, a] = lo[i, a] * vox[a], hi[i, a] * vox[a]
                pts = index.points_in(lo[i], hi[i])
                lo_m[i, a], hi_m[i, a] = refine_extent(pts[:, a], lo_m[i, a], hi_m[i, a], settings.refine_bin)
    if settings.refine and index is not None:
        refine_reveals(lo, hi, lo_m, hi_m, cls_all, grid, index)  # doors' depth, columns' sides
        if model.boxfit is not None and settings.box_fit:
            model.boxfit.apply(lo_m, hi_m, cls_all, index.points_in_metric, np.asarray(vol.frame.extent, float))
    score = np.concatenate(sc_all)
    if settings.refine and index is not None and model.rescorer is not None and settings.rescore:
        score = model.rescorer.apply(score, cls_all, lo_m, hi_m, index.points_in_metric,
                                     np.asarray(vol.frame.extent, float))
    return Detections(lo, hi, lo_m, hi_m, score, cls_all, at_all_cat)


def surface_order(keep: np.ndarray, lo: np.ndarray, hi: np.ndarray, nz: int, upper: bool,
                  choice: str = "extreme") -> np.ndarray:
    """A space's ceiling (``upper``) or floor windows ``keep`` (best score first) in the order its one is taken from.

    ``"extreme"``: highest top first for a ceiling, lowest bottom first for a floor (ties by
    score): a room's ceiling is its highest horizontal surface, its floor its lowest, while
    beams' undersides, table tops and shelves can outscore them.  ``"halves"``: the windows
    whose middle lies in the upper (ceiling) or lower (floor) half of the space's ``nz``
    voxels, best first (all of them if none does).  ``"score"``: unchanged (best first).
    """
    if not len(keep) or choice == "score":
        return keep
    if choice == "halves":
        mid = (lo[keep, 2] + hi[keep, 2]) / 2.0
        ok = mid >= nz / 2.0 if upper else mid <= nz / 2.0
        return keep[ok] if ok.any() else keep
    z = hi[keep, 2] if upper else -lo[keep, 2]
    return keep[np.argsort(-z, kind="stable")]


def to_proposals(det: Detections, vol: SpaceVolume, model: Model, space_id: int,
                 origin: np.ndarray) -> list[Proposal]:
    """Detections as :class:`Proposal` objects in world coordinates (``origin`` = store-local to world shift)."""
    f = vol.frame
    world = CanonicalFrame(f.yaw, f.origin + np.asarray(origin, dtype=np.float64), f.extent, f.entrance, f.info)
    out = []
    atoms = model.dictionary.atoms_
    for i in range(len(det.score)):
        p = det.lo_m[i] / f.extent
        s = (det.hi_m[i] - det.lo_m[i]) / f.extent
        center, size, yaw = world.unit_box_to_world(p, s)
        out.append(Proposal(space_id=int(space_id), class_code=int(det.class_code[i]), score=float(det.score[i]),
                            position=p, size=s, occupancy=atoms[int(det.atom[i])].occupancy.copy(),
                            center=center, world_size=size, yaw=float(yaw),
                            extra={"atom": int(det.atom[i])}))
    return out


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


def detect_space(points: SpacePoints, model: Model, settings: DetectionSettings | None = None,
                 origin: np.ndarray | None = None, connection: np.ndarray | None = None) -> list[Proposal]:
    """All proposals of one space (its points in store-local coordinates)."""
    settings = settings or DetectionSettings.from_config()
    if len(points.xyz) < max(settings.min_window_points, 4):
        return []
    vol, index = prepare_indexed(points, model, space_frame(points, connection), settings.refine)
    det = detect_in_volume(vol, model, settings, index)
    return to_proposals(det, vol, model, points.space_id, np.zeros(3) if origin is None else origin)


def by_size(refs: list[SpaceRef]) -> list[SpaceRef]:
    """Spaces in the order their tasks should start: most points first (ties by id), the longest tasks first."""
    return sorted(refs, key=lambda r: (-r.count, r.space_id))


def _detect_task(job: tuple[SpaceRef, np.ndarray | None], store, model: Model, space_array: str,
                 settings: DetectionSettings) -> list[Proposal]:
    ref, hint = job
    points = load_space(store, ref, space_array)
    return detect_space(points, model, settings, np.asarray(store.meta.origin, dtype=np.float64), hint)


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
    hints = connection_hints(store, space_array)
    if client is not None and refs:
        [model_arg] = client.scatter([model], broadcast=True)
    else:
        model_arg = model
    # largest spaces first: dask starts tasks in submission order, so the long ones do not end the stage with
    # one worker idle (a space's task time grows with its points; the medium bench_run building, 15 spaces on
    # 2 workers: the largest space, 20 % of the stage's task seconds, came ninth by id and ran alone at the end)
    refs = by_size(refs)
    results = run_tasks(_detect_task, [(r, hints.get(r.space_id)) for r in refs], client=client,
                        label="detect elements",
                        keys=[f"space {r.space_id}" for r in refs],
                        extra_args=(store, model_arg, space_array, settings))
    # by space, class and score as before; the sort is stable, so ties keep their order within a space
    proposals = [p for r in results for p in r]
    proposals.sort(key=lambda p: (p.space_id, p.class_code, -p.score))
    for i, p in enumerate(proposals):
        p.element_id = i
    return proposals
