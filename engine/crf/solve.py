"""The integer program (2) of paper 4.1: the labelling that maximises equation (1), solved with CP-SAT.

One auxiliary ``y_uv`` per edge with only the constraints the objective presses on; integer
coefficients (energies scaled to ``objective-resolution``); one search worker, a fixed seed and a
deterministic-time budget, so a solve is reproducible.  Nodes of the classes the CRF does not decide
enter with fixed labels (:func:`fix_labels`).  Design notes: ``docs/design/crf.md``.
"""
from __future__ import annotations

import time
from typing import Any

import numpy as np

from engine.crf.graph import CRFGraph, energy
from engine.crf.model import CRFSettings, CRFWeights
from tiles.classes import ELEMENT_CLASSES


def solve_ip(unary: np.ndarray, edges: np.ndarray, pairwise: np.ndarray,
             settings: CRFSettings | None = None) -> tuple[np.ndarray, dict[str, Any]]:
    """Maximise equation (1) as the integer program (2) with CP-SAT.

    Parameters
    ----------
    unary
        ``(n,)`` energy of keeping each node.
    edges, pairwise
        ``(m, 2)`` node pairs and ``(m,)`` energy of keeping both ends.
    settings
        Solver settings; None reads ``buildingparser.crf.*``.

    Returns
    -------
    y, info
        ``(n,)`` bool labels and ``{"status", "seconds", "objective", "bound", "variables", "edges",
        "warning"}``; ``status`` is CP-SAT's name (``OPTIMAL``, ``FEASIBLE``...), or ``TRIVIAL`` when no
        edge was left (the labels are then the unary signs, which is optimal).
    """
    from ortools.sat.python import cp_model

    settings = settings or CRFSettings.from_config()
    unary = np.asarray(unary, dtype=np.float64)
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    pairwise = np.asarray(pairwise, dtype=np.float64)
    n = len(unary)
    if len(pairwise) != len(edges):
        raise ValueError("one pairwise energy per edge expected")
    if not (np.all(np.isfinite(unary)) and np.all(np.isfinite(pairwise))):
        raise ValueError("energies must be finite")
    t0 = time.perf_counter()
    unary_only = unary > 0
    top = max(float(np.abs(unary).max(initial=0.0)), float(np.abs(pairwise).max(initial=0.0)))
    scale = settings.resolution / top if top > 0 else 0.0
    cu = np.rint(unary * scale).astype(np.int64)
    cp = np.rint(pairwise * scale).astype(np.int64)
    keep_e = cp != 0
    e_used, c_used = edges[keep_e], cp[keep_e]
    info: dict[str, Any] = {"variables": 0, "edges": int(len(e_used)), "scale": scale, "warning": None}
    y = unary_only.copy()
    if len(e_used) == 0:
        info.update(status="TRIVIAL", objective=energy(unary, edges, pairwise, y), bound=None,
                    seconds=time.perf_counter() - t0)
        return y, info
    active = np.unique(e_used.ravel())  # nodes without an edge are decided by their sign, above
    model, yv, zv = _program(n, active, e_used, c_used, cu)
    solver = _solver(settings)
    status = solver.solve(model)
    name = solver.status_name(status)
    info["variables"] = len(yv) + len(zv)
    if status in (cp_model.OPTIMAL, cp_model.FEASIBLE):
        y[active] = np.array(solver.boolean_values(yv), dtype=bool)
        info["bound"] = solver.best_objective_bound / scale
        if status == cp_model.FEASIBLE:
            info["warning"] = (f"CRF not solved to optimality within its limits ({len(active)} nodes, "
                               f"{len(e_used)} edges): best feasible solution kept")
    else:
        info["bound"] = None
        info["warning"] = f"CRF solver found no solution ({name}): unary-only labels kept"
    info.update(status=name, objective=energy(unary, edges, pairwise, y), seconds=time.perf_counter() - t0)
    return y, info


def _program(n: int, active: np.ndarray, e_used: np.ndarray, c_used: np.ndarray,
             cu: np.ndarray) -> tuple[Any, list, list]:
    """The CP-SAT model of the ``active`` nodes and the edges ``e_used`` (integer energies ``cu``, ``c_used``):
    the model, its node variables (in ``active`` order) and its edge variables."""
    from ortools.sat.python import cp_model

    local = np.full(n, -1, dtype=np.int64)
    local[active] = np.arange(len(active))
    model = cp_model.CpModel()
    yv = [model.new_bool_var(f"y{v}") for v in active]
    zv = []
    for (a, b), c in zip(e_used, c_used):
        ya, yb = yv[local[a]], yv[local[b]]
        z = model.new_bool_var(f"y{a}_{b}")
        if c > 0:  # the objective pushes z up: only y_uv <= y_u, y_uv <= y_v bind
            model.add_implication(z, ya)
            model.add_implication(z, yb)
        else:  # it pushes z down: only y_u + y_v <= y_uv + 1 binds
            model.add_bool_or([ya.Not(), yb.Not(), z])
        zv.append(z)
    model.maximize(cp_model.LinearExpr.weighted_sum(yv + zv, [int(c) for c in cu[active]] + [int(c) for c in c_used]))
    return model, yv, zv


def _solver(settings: CRFSettings) -> Any:
    """A CP-SAT solver with the CRF's parameters: one worker, the linearization level, seed and limits."""
    from ortools.sat.python import cp_model

    solver = cp_model.CpSolver()
    p = solver.parameters
    p.num_workers = 1
    p.linearization_level = settings.linearization_level
    p.random_seed = settings.seed
    p.max_deterministic_time = settings.deterministic_time
    p.max_time_in_seconds = settings.time_limit
    p.log_search_progress = False
    return solver


def fixed_labels(graph: CRFGraph, weights: CRFWeights, keep: tuple[str, ...] = (),
                 sure: np.ndarray | None = None) -> np.ndarray | None:
    """Per node: 1 for the nodes of the classes ``keep`` and the ``sure`` nodes (always kept), 1/0 for those of
    classes the CRF does not decide (the detector's score > 0), -1 for the free ones; None when every node is
    free."""
    kept = np.isin(graph.classes, [ELEMENT_CLASSES.index(c) for c in keep])
    if sure is not None:
        kept |= np.asarray(sure, dtype=bool)
    fixed = ~weights.decides[graph.classes] | kept
    if not fixed.any():
        return None
    return np.where(kept, 1, np.where(fixed, (graph.scores > 0).astype(np.int64), -1))


def fix_labels(unary: np.ndarray, edges: np.ndarray, pairwise: np.ndarray,
               labels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The integer program of the free nodes (``labels == -1``) with the others' labels (0/1) put in.

    An edge to a kept fixed node adds its energy to the free end's unary term; edges to dropped fixed
    nodes, and between fixed nodes, are constants and leave.  Node indices are kept; a fixed node's
    unary becomes 0 (it has no edge left: the caller sets its label).
    """
    labels = np.asarray(labels, dtype=np.int64)
    fixed = labels >= 0
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    fu, fv = fixed[edges[:, 0]], fixed[edges[:, 1]]
    out = np.where(fixed, 0.0, unary)
    one = fu != fv
    free_end = np.where(fu, edges[:, 1], edges[:, 0])[one]
    fixed_end = np.where(fu, edges[:, 0], edges[:, 1])[one]
    np.add.at(out, free_end, pairwise[one] * (labels[fixed_end] == 1))
    both_free = ~fu & ~fv
    return out, edges[both_free], np.asarray(pairwise)[both_free]


def solve_fixed(unary: np.ndarray, edges: np.ndarray, pairwise: np.ndarray, labels: np.ndarray | None,
                settings: CRFSettings | None = None) -> tuple[np.ndarray, dict[str, Any]]:
    """:func:`solve_ip` with some labels fixed (``labels``: 0/1 fixed, -1 free; None: all free).

    The free nodes get the labels that maximise equation (1) given the fixed ones; ``objective`` is
    the energy of the whole labelling.
    """
    if labels is None:
        return solve_ip(unary, edges, pairwise, settings)
    u2, e2, p2 = fix_labels(unary, edges, pairwise, labels)
    y, info = solve_ip(u2, e2, p2, settings)
    y = np.where(labels >= 0, labels == 1, y)
    info["objective"] = energy(unary, edges, pairwise, y)
    return y, info
