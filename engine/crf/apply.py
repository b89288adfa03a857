"""The CRF over the spaces of a building (paper 4.1): the elements each space keeps, and their scores in context.

:func:`select_elements` runs one space's CRF (graph, energies, integer program); :func:`apply_crf`
runs every space as one dask task and reports the solves for ``metrics.json``.  Every proposal gets
its contextual score (:func:`flip_margins`) in ``extra["crf_margin"]``.  Design notes:
``docs/design/crf.md``.
"""
from __future__ import annotations

import dataclasses
import statistics
import time
import warnings
from collections import Counter
from typing import Any

import numpy as np

from engine.crf.graph import build_graph, energies
from engine.crf.model import CRFSettings, CRFWeights
from engine.crf.solve import fixed_labels, solve_fixed
from engine.detection.proposals import SURE, Proposal
from tiles.classes import ELEMENT_CLASSES
from tiles.tasks import run_tasks

#: Key of ``Proposal.extra`` where the CRF leaves each proposal's contextual score (:func:`flip_margins`).
MARGIN = "crf_margin"


def flip_margins(unary: np.ndarray, edges: np.ndarray, pairwise: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Energy gained by keeping each node, the others' labels fixed: ``E(y, y_v=1) - E(y, y_v=0)``.

    At the CRF's optimum it is >= 0 for the kept nodes and <= 0 for the dropped
    ones (up to the integer rounding), and it ranks proposals by the detector's
    score *in context*: a duplicate of a kept box is pushed down by its pairwise
    penalty, a chair next to a kept table is pulled up.  :func:`rescored` turns
    it into proposal scores.
    """
    y = np.asarray(y, dtype=bool)
    m = np.asarray(unary, dtype=np.float64).copy()
    if len(edges):
        np.add.at(m, edges[:, 0], pairwise * y[edges[:, 1]])
        np.add.at(m, edges[:, 1], pairwise * y[edges[:, 0]])
    return m


def rescored(proposals: list[Proposal]) -> list[Proposal]:
    """Copies of the proposals with the CRF's contextual score (``extra["crf_margin"]``) as their ``score``.

    For ranking: the average precision of all proposals ranked by this score is
    the CRF's effect on the ranked list, next to the final set it keeps.
    """
    out = []
    for p in proposals:
        if MARGIN not in p.extra:
            raise ValueError("proposal without a CRF margin: run select_elements or apply_crf first")
        out.append(dataclasses.replace(p, score=float(p.extra[MARGIN]), extra=dict(p.extra)))
    return out


def select_elements(proposals: list[Proposal], weights: CRFWeights, *,
                    settings: CRFSettings | None = None) -> tuple[list[Proposal], dict[str, Any]]:
    """The CRF of one space: the proposals to keep (in their input order) and how the solve went.

    Parameters
    ----------
    proposals
        The proposals of one space.
    weights
        Trained (or hand-set) :class:`CRFWeights`; its ``grid`` must match the occupancy patterns.
    settings
        Graph bound and solver settings; None reads ``buildingparser.crf.*``.

    Returns
    -------
    kept, info
        ``info`` has ``space_id``, ``status``, ``seconds`` (graph + solve), ``solver_seconds``,
        ``nodes``, ``edges``, ``kept``, ``objective`` and ``warning`` (also issued as a Python warning).
        Every proposal gets its contextual score in ``extra["crf_margin"]`` (:func:`flip_margins`).
    """
    keep, margin, info = select_space(proposals, weights, settings)
    if info["warning"]:
        warnings.warn(info["warning"], RuntimeWarning, stacklevel=2)
    for p, m in zip(proposals, margin):
        p.extra[MARGIN] = float(m)
    return [p for p, k in zip(proposals, keep) if k], info


def select_space(proposals: list[Proposal], weights: CRFWeights,
                 settings: CRFSettings | None = None) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """:func:`select_elements` without side effects: keep mask, margins, info (the task of one space: the
    driver issues the warnings)."""
    if not isinstance(weights, CRFWeights):
        raise TypeError(f"weights must be CRFWeights, not {type(weights).__name__}")
    settings = settings or CRFSettings.from_config()
    t0 = time.perf_counter()
    space_ids = sorted({int(p.space_id) for p in proposals})
    if len(space_ids) > 1:
        raise ValueError(f"select_elements works on one space, got proposals of spaces {space_ids}")
    sid = space_ids[0] if space_ids else None
    if not proposals:
        return np.zeros(0, dtype=bool), np.zeros(0), {
            "space_id": sid, "status": "EMPTY", "seconds": 0.0, "solver_seconds": 0.0, "nodes": 0, "edges": 0,
            "kept": 0, "objective": 0.0, "warning": None}
    graph = build_graph(proposals, weights.k, weights.grid, max_nodes_per_class=settings.max_nodes_per_class)
    unary, pairwise = energies(graph, weights)
    sure = np.array([bool(p.extra.get(SURE)) for p in proposals], dtype=bool)  # a wall at a side (detection.sides)
    y, sinfo = solve_fixed(unary, graph.edges, pairwise, fixed_labels(graph, weights, settings.keep_classes, sure),
                           settings)
    warning = f"space {sid}: {sinfo['warning']}" if sinfo["warning"] else None
    info = {"space_id": sid, "status": sinfo["status"], "seconds": time.perf_counter() - t0,
            "solver_seconds": sinfo["seconds"], "nodes": graph.n, "edges": graph.m, "kept": int(y.sum()),
            "objective": sinfo["objective"], "warning": warning}
    return y, flip_margins(unary, graph.edges, pairwise, y), info


def apply_crf(proposals: list[Proposal], weights: CRFWeights, client=None, *,
              settings: CRFSettings | None = None) -> tuple[list[Proposal], dict[str, Any]]:
    """Run the CRF of every space, one dask task per space.

    Parameters
    ----------
    proposals
        Proposals of any number of spaces.
    weights
        The CRF weights (scattered once to the workers).
    client
        A ``distributed.Client``; None runs the spaces one after another here.
    settings
        None reads ``buildingparser.crf.*`` here, on the driver, and sends them to the tasks.

    Returns
    -------
    kept, report
        The kept proposals in their input order (every input proposal gets its contextual score in
        ``extra["crf_margin"]``, :func:`flip_margins`), and the ``crf`` block of ``metrics.json``:
        ``{"spaces", "solve_seconds": {"median", "max"}, "status": {name: count}, "proposals", "kept",
        "decides": [class, ...], "always_kept": [class, ...], "per_space": [info, ...]}`` (``solve_seconds``
        is graph building + solving, per space; ``decides``: the classes whose keep/drop the CRF decided, the
        others kept the detector's decision; ``always_kept``: ``crf.keep-classes``, kept whatever their score).
    """
    if not isinstance(weights, CRFWeights):
        raise TypeError(f"weights must be CRFWeights, not {type(weights).__name__}")
    settings = settings or CRFSettings.from_config()
    groups: dict[int, list[int]] = {}
    for i, p in enumerate(proposals):
        groups.setdefault(int(p.space_id), []).append(i)
    sids = sorted(groups)
    items = [[proposals[i] for i in groups[s]] for s in sids]
    w_arg: Any = weights
    if client is not None and items:
        w_arg = client.scatter(weights, broadcast=True, hash=False)
    # the spaces with most proposals first (the solve grows with them): no long task left alone at the end
    order = sorted(range(len(sids)), key=lambda k: (-len(items[k]), sids[k]))
    done = run_tasks(select_space, [items[k] for k in order], client=client, label="CRF per space",
                       keys=[f"space {sids[k]}" for k in order], extra_args=(w_arg, settings))
    results: list[Any] = [None] * len(sids)
    for k, r in zip(order, done):
        results[k] = r
    keep = np.zeros(len(proposals), dtype=bool)
    infos = []
    for sid, (mask, margin, info) in zip(sids, results):
        idx = np.asarray(groups[sid])
        keep[idx[mask]] = True
        for i, m in zip(idx, margin):
            proposals[i].extra[MARGIN] = float(m)
        infos.append(info)
        if info.get("warning"):
            warnings.warn(info["warning"], RuntimeWarning, stacklevel=2)
    secs = [float(i["seconds"]) for i in infos]
    report = {"spaces": len(sids),
              "solve_seconds": {"median": statistics.median(secs) if secs else 0.0, "max": max(secs, default=0.0)},
              "status": dict(sorted(Counter(i["status"] for i in infos).items())),
              "proposals": len(proposals), "kept": int(keep.sum()),
              "decides": [c for c, d in zip(ELEMENT_CLASSES, weights.decides) if d],
              "always_kept": list(settings.keep_classes), "per_space": infos}
    return [p for p, k in zip(proposals, keep) if k], report


def metrics_block(report: dict[str, Any]) -> dict[str, Any]:
    """The ``crf`` block of ``metrics.json`` from an :func:`apply_crf` report (without the per-space details)."""
    return {k: report[k] for k in ("spaces", "solve_seconds", "status", "proposals", "kept", "decides",
                                   "always_kept") if k in report}
