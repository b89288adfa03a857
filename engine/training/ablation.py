"""Several models of one window dictionary detected in one pass (the feature ablations of paper Table 3).

The ablated models of :func:`engine.training.svm.refit_without` share the full
model's dictionary, voxel grid and colour normalisation and differ only in
their SVM weights (zero on the groups they leave out).  Detecting each of them
alone repeats, per space, the costly part: loading the points, the canonical
frame, the moments and, per window shape, the features of every sliding
position.  Here each space is prepared once and every window shape is scored
for all models' weights at once (:func:`engine.detection.sliding.score_windows_many`);
NMS, local search and refinement then run per model
(:func:`engine.detection.space.detect_in_volume` with the precomputed candidates).
The proposals are those of :func:`engine.detection.detect.detect` with each model, to
rounding of the scores (tested).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from engine.detection.candidates import top_windows
from engine.detection.model import Model
from engine.detection.proposals import Proposal
from engine.detection.settings import DetectionSettings
from engine.detection.sliding import score_windows_many, window_shape
from engine.detection.space import detect_in_volume, prepare_indexed, space_frame, to_proposals
from engine.detection.volume import SpaceVolume
from engine.spaces.points import SpacePoints, SpaceRef, index_spaces, load_space
from tiles.tasks import run_tasks


def check_compatible(models: list[Model]) -> None:
    """Raise ``ValueError`` unless the models share dictionary, grid, K, colour normalisation and global block."""
    if not models:
        raise ValueError("no models")
    m0 = models[0]
    a0 = m0.dictionary.to_arrays()
    for m in models[1:]:
        a = m.dictionary.to_arrays()
        same = all(np.array_equal(a[k], a0[k]) for k in a0) and m.voxel == m0.voxel and \
            m.max_cells == m0.max_cells and m.layout.k == m0.layout.k and m.layout.colour == m0.layout.colour and \
            m.layout.min_points == m0.layout.min_points and m.layout.boundary == m0.layout.boundary
        if not same:
            raise ValueError("models of one pass need the same dictionary, voxel grid, K, colour normalisation and "
                             "global block")


def window_candidates_many(vol: SpaceVolume, models: list[Model],
                           settings: DetectionSettings) -> list[dict[int, tuple[np.ndarray, ...]]]:
    """:func:`engine.detection.candidates.window_candidates` of every model, each window shape scored once for all."""
    m0 = models[0]
    grid = vol.grid
    # weights zero on each model's disabled groups: one layout without any disabled group scores them all
    full = dataclasses.replace(m0.layout, disabled=())
    groups: dict[tuple[int, ...], list[tuple[int, int]]] = {}
    for ai, atom in enumerate(m0.dictionary.atoms_):
        shape = tuple(int(v) for v in window_shape(atom.size_in(grid.extent), grid))
        for mi, m in enumerate(models):
            if m.trained[atom.class_code]:
                groups.setdefault(shape, []).append((mi, ai))
    out: list[dict[int, tuple[np.ndarray, ...]]] = [{} for _ in models]
    for shape, members in groups.items():
        rows = [models[mi].window_weights([ai]) for mi, ai in members]
        w = np.stack([r[0][0] * models[mi].layout.mask for r, (mi, _) in zip(rows, members)])
        b = np.array([r[1][0] for r in rows])
        scored = score_windows_many(vol, np.array(shape), w, b, full, settings.stride, settings.min_window_points,
                                    settings.max_stride)
        for (mi, ai), ws in zip(members, scored):
            top = top_windows(ws, ai, settings)
            if top is not None:
                out[mi][ai] = top
    return out


def detect_space_many(points: SpacePoints, models: list[Model], settings: DetectionSettings,
                      origin: np.ndarray | None = None) -> list[list[Proposal]]:
    """Per model, the proposals of one space (as :func:`engine.detection.space.detect_space` gives them)."""
    if len(points.xyz) < max(settings.min_window_points, 4):
        return [[] for _ in models]
    vol, index = prepare_indexed(points, models[0], space_frame(points), settings.refine)
    origin = np.zeros(3) if origin is None else origin
    out = []
    for m, cand in zip(models, window_candidates_many(vol, models, settings)):
        det = detect_in_volume(vol, m, settings, index, candidates=cand)
        out.append(to_proposals(det, vol, m, points.space_id, origin))
    return out


def _task(ref: SpaceRef, store, models: list[Model], space_array: str,
          settings: DetectionSettings) -> list[list[Proposal]]:
    points = load_space(store, ref, space_array)
    return detect_space_many(points, models, settings, np.asarray(store.meta.origin, dtype=np.float64))


def detect_many(store, models: list[Model], *, client=None, space_array: str = "gt_space",
                settings: DetectionSettings | None = None) -> list[list[Proposal]]:
    """Per model, the proposals of every space of ``store`` (one dask task per space for all models).

    Parameters
    ----------
    store
        A tile store with per-point ``space_array`` ids.
    models
        Models sharing one dictionary, voxel grid, K and colour normalisation (:func:`check_compatible`).
    client
        A ``distributed.Client``; None runs here.
    space_array
        ``"gt_space"`` or ``"space_id"``.  Without ``meta/spaces`` connection hints (the frame's
        entrance is found from the points alone), as :func:`engine.detection.detect.detect` on ground-truth spaces.
    settings
        Detection settings; default from ``buildingparser.detection.*``.

    Returns
    -------
    One list of proposals per model, numbered like :func:`engine.detection.detect.detect`'s.
    """
    check_compatible(models)
    settings = settings or DetectionSettings.from_config()
    refs = index_spaces(store, space_array, client=client)
    arg = models
    if client is not None and refs:
        [arg] = client.scatter([models], broadcast=True)
    res = run_tasks(_task, refs, client=client, label="detect elements (several models)",
                    keys=[f"space {r.space_id}" for r in refs], extra_args=(store, arg, space_array, settings))
    out = []
    for mi in range(len(models)):
        props = [p for r in res for p in r[mi]]
        props.sort(key=lambda p: (p.space_id, p.class_code, -p.score))
        for i, p in enumerate(props):
            p.element_id = i
        out.append(props)
    return out
