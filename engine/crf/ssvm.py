"""Learning the CRF weights (paper 4.1) with a structured SVM [35]: 1-slack cutting planes.

The weights minimise ``lambda/2 |w|^2 + 1/n sum_i max_y [Delta(y*_i, y) + w . Psi(x_i, y) - w . Psi(x_i, y*_i)]``
with ``Delta`` a weighted Hamming loss (:func:`hamming_loss`).  Each iteration runs the loss-augmented
inference of every space (one dask task per space) and re-solves the small dual over the cutting planes
found so far (:func:`solve_working_set`); deterministic on any cluster.  :func:`train_crf` labels the
proposals, chooses the miss cost and the classes the CRF decides (:mod:`engine.crf.validation`) and fits.
Design notes: ``docs/design/crf.md``.
"""
from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from engine import config
from engine.crf.graph import build_graph, energies, joint_feature
from engine.crf.labels import label_spaces
from engine.crf.model import CRFSettings, CRFWeights
from engine.crf.solve import solve_ip
from engine.crf.validation import choose
from engine.detection.proposals import Proposal
from tiles.tasks import run_tasks


# -----------------------------------------------------------------------------------------
# Oracles (dask tasks)
# -----------------------------------------------------------------------------------------
def hamming_loss(ystar: np.ndarray, y: np.ndarray, miss_cost: float = 1.0) -> float:
    """Weighted Hamming loss: ``miss_cost`` per true element dropped, 1 per false one kept."""
    ystar, y = np.asarray(ystar, dtype=bool), np.asarray(y, dtype=bool)
    return float(miss_cost * np.sum(ystar & ~y) + np.sum(~ystar & y))


def _oracle(example: tuple[list[Proposal], np.ndarray], weights: CRFWeights,
            settings: CRFSettings, miss_cost: float) -> dict[str, Any]:
    """Loss-augmented inference of one space at ``weights``: ``psi = Psi(y*) - Psi(y_hat)`` and the loss."""
    proposals, ystar = example
    graph = build_graph(proposals, weights.k, weights.grid, max_nodes_per_class=settings.max_nodes_per_class)
    unary, pairwise = energies(graph, weights)
    # the loss is linear in y: miss_cost * y* (1 - y) + (1 - y*) y = const + (1 - y* - miss_cost y*) y
    yhat, info = solve_ip(unary + np.where(ystar, -miss_cost, 1.0), graph.edges, pairwise, settings)
    psi = joint_feature(graph, ystar) - joint_feature(graph, yhat)
    loss = hamming_loss(ystar, yhat, miss_cost)
    return {"psi": psi, "loss": loss, "hinge": loss - float(weights.vector() @ psi), "status": info["status"]}


def _predict(example: tuple[list[Proposal], np.ndarray], weights: CRFWeights, settings: CRFSettings) -> dict[str, Any]:
    """Plain inference of one space and its Hamming loss against ``y*``."""
    proposals, ystar = example
    graph = build_graph(proposals, weights.k, weights.grid, max_nodes_per_class=settings.max_nodes_per_class)
    unary, pairwise = energies(graph, weights)
    y, info = solve_ip(unary, graph.edges, pairwise, settings)
    return {"errors": int(np.sum(y != ystar)), "nodes": len(y), "status": info["status"]}


# -----------------------------------------------------------------------------------------
# 1-slack cutting planes
# -----------------------------------------------------------------------------------------
@dataclass
class SSVMResult:
    """The learnt weights and how training went.

    ``history`` has one dict per iteration: ``iteration``, ``primal`` (the exact
    S-SVM objective at that iteration's weights: every space's most violating
    labelling is found), ``dual`` (the working-set QP's value, a lower bound on
    the optimum), ``gap`` (best primal so far minus dual), ``planes`` and
    ``seconds``.  ``objective`` gives the objective at w = 0 (``"initial"``: the
    mean over spaces of the loss of flipping every label) and at the returned
    weights (``"final"``, the lowest primal seen).  ``errors`` gives the mean
    Hamming error per proposal of plain inference: ``"initial"`` for the
    untrained weights (keep the proposals with a positive score), ``"final"``
    for the learnt ones.  ``statuses`` counts the solver statuses of the oracles.
    """

    weights: CRFWeights
    history: list[dict[str, Any]] = field(default_factory=list)
    errors: dict[str, float] = field(default_factory=dict)
    objective: dict[str, float] = field(default_factory=dict)
    converged: bool = False
    statuses: dict[str, int] = field(default_factory=dict)


def solve_working_set(planes: np.ndarray, losses: np.ndarray, lam: float,
                      start: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """The 1-slack dual over the working set: weights of the planes and the dual value.

    Maximises ``alpha . losses - |alpha @ planes|^2 / (2 lam)`` over ``alpha >= 0``,
    ``sum(alpha) <= 1`` (SciPy's SLSQP; a zero plane with zero loss turns the
    inequality into the simplex).  The weights are then ``alpha @ planes / lam``.
    """
    from scipy.optimize import minimize

    c = len(losses)
    gram = planes @ planes.T / lam
    h = np.zeros((c + 1, c + 1))
    h[1:, 1:] = gram
    lin = np.r_[0.0, losses]
    x0 = np.full(c + 1, 1.0 / (c + 1)) if start is None else np.r_[max(0.0, 1 - start.sum()), start]

    def f(a: np.ndarray) -> tuple[float, np.ndarray]:
        ha = h @ a
        return 0.5 * float(a @ ha) - float(lin @ a), ha - lin

    res = minimize(f, x0, jac=True, method="SLSQP", bounds=[(0.0, 1.0)] * (c + 1),
                   constraints=[{"type": "eq", "fun": lambda a: a.sum() - 1.0, "jac": lambda a: np.ones_like(a)}],
                   options={"ftol": 1e-12, "maxiter": 1000})
    alpha = np.clip(res.x[1:], 0.0, None)
    if alpha.sum() > 1:
        alpha /= alpha.sum()
    wv = alpha @ planes / lam
    return alpha, float(alpha @ losses - lam / 2 * wv @ wv)


def fit_ssvm(examples: Sequence[tuple[list[Proposal], np.ndarray]], init: CRFWeights, *, lam: float | None = None,
             iterations: int | None = None, tol: float | None = None, miss_cost: float | None = None,
             client=None, settings: CRFSettings | None = None) -> SSVMResult:
    """Fit the CRF weights on labelled spaces with the 1-slack cutting-plane S-SVM.

    Each iteration runs the loss-augmented inference of every space at the
    current weights (one dask task per space), adds their mean as one cutting
    plane, and re-solves the small dual QP over all planes
    (:func:`solve_working_set`).  Everything is deterministic.

    Parameters
    ----------
    examples
        ``(proposals, y*)`` per space (spaces without proposals are skipped).
    init
        Gives the shape (``grid``, ``k_e``); its values are not used (training starts at w = 0).
    lam, iterations, tol
        Regularisation, most iterations, and the stop: (best primal - dual) <= tol * best primal;
        None reads ``buildingparser.crf.ssvm.*``.
    miss_cost
        Loss of dropping a true element, relative to keeping a false one (see :func:`hamming_loss`);
        None reads ``buildingparser.crf.ssvm.miss-cost``.
    client
        A ``distributed.Client``; None runs the oracles here.
    settings
        CRF graph and solver settings; None reads ``buildingparser.crf.*``.
    """
    lam, iterations, tol, miss_cost = _ssvm_parameters(lam, iterations, tol, miss_cost)
    settings = settings or CRFSettings.from_config()
    examples = [(list(p), np.asarray(y, dtype=bool)) for p, y in examples if len(p)]
    for p, y in examples:
        if len(y) != len(p):
            raise ValueError("one label per proposal expected")
    n = len(examples)
    if n == 0:
        raise ValueError("no training space has proposals")
    items: list[Any] = examples
    if client is not None:
        items = client.scatter(examples, hash=False)
    w = np.zeros(init.size)
    best_w, best_primal = w.copy(), math.inf
    planes: list[np.ndarray] = []
    losses: list[float] = []
    alpha: np.ndarray | None = None
    dual = 0.0
    result = SSVMResult(init.with_vector(w))
    statuses: dict[str, int] = {}
    for it in range(1, iterations + 1):
        t0 = time.perf_counter()
        outs = run_tasks(_oracle, items, client=client, label=f"S-SVM iteration {it}",
                         keys=[f"space #{i}" for i in range(n)], extra_args=(init.with_vector(w), settings, miss_cost))
        for o in outs:
            statuses[o["status"]] = statuses.get(o["status"], 0) + 1
        g = np.mean([o["psi"] for o in outs], axis=0)
        loss = float(np.mean([o["loss"] for o in outs]))
        primal = lam / 2 * float(w @ w) + max(0.0, loss - float(w @ g))
        if primal < best_primal:
            best_primal, best_w = primal, w.copy()
        gap = best_primal - dual
        result.history.append({"iteration": it, "primal": primal, "dual": dual, "gap": gap,
                               "planes": len(planes), "seconds": time.perf_counter() - t0})
        if gap <= tol * max(best_primal, 1e-12):
            result.converged = True
            break
        planes.append(g)
        losses.append(loss)
        alpha, dual = solve_working_set(np.array(planes), np.array(losses), lam,
                                        None if alpha is None else np.r_[alpha, 0.0])
        w = alpha @ np.array(planes) / lam
        result.history[-1]["seconds"] = time.perf_counter() - t0
    result.weights = init.with_vector(best_w)
    result.statuses = dict(sorted(statuses.items()))
    result.errors = {"initial": _error_rate(examples, None), "final": _error_rate(
        items, result.weights, client=client, settings=settings, total=sum(len(p) for p, _ in examples))}
    result.objective = {"initial": float(np.mean([hamming_loss(y, ~y, miss_cost) for _, y in examples])),
                        "final": best_primal}
    return result


def _ssvm_parameters(lam: float | None, iterations: int | None, tol: float | None,
                     miss_cost: float | None) -> tuple[float, int, float, float]:
    """The S-SVM's ``lam``, ``iterations``, ``tol`` and ``miss_cost``, checked (None: ``buildingparser.crf.ssvm.*``)."""
    lam = float(config.setting("crf.ssvm.lam") if lam is None else lam)
    iterations = int(config.setting("crf.ssvm.iterations") if iterations is None else iterations)
    tol = float(config.setting("crf.ssvm.tol") if tol is None else tol)
    miss_cost = float(config.setting("crf.ssvm.miss-cost") if miss_cost is None else miss_cost)
    if not (lam > 0 and math.isfinite(lam)):
        raise ValueError(f"lam must be positive, not {lam}")
    if iterations < 1:
        raise ValueError(f"iterations must be >= 1, not {iterations}")
    if tol < 0:
        raise ValueError(f"tol must be >= 0, not {tol}")
    if not (miss_cost > 0 and math.isfinite(miss_cost)):
        raise ValueError(f"miss_cost must be positive, not {miss_cost}")
    return lam, iterations, tol, miss_cost


def ssvm_objective(examples: Sequence[Any], weights: CRFWeights, lam: float, *, miss_cost: float = 1.0,
                   client=None, settings: CRFSettings | None = None) -> float:
    """The S-SVM objective ``lambda/2 |w|^2 + mean_i max_y [loss + w.Psi(y) - w.Psi(y*)]`` at ``weights``.

    ``examples`` are ``(proposals, y*)`` pairs (or futures of them); one loss-augmented inference per space.
    """
    settings = settings or CRFSettings.from_config()
    outs = run_tasks(_oracle, list(examples), client=client, label="S-SVM objective",
                     extra_args=(weights, settings, float(miss_cost)))
    w = weights.vector()
    return lam / 2 * float(w @ w) + float(np.mean([o["hinge"] for o in outs]))


def _error_rate(items: Sequence[Any], weights: CRFWeights | None, *, client=None, settings: CRFSettings | None = None,
                total: int | None = None) -> float:
    """Mean Hamming error per proposal of plain inference (None: keep the proposals with a positive score)."""
    if weights is None:
        errs = sum(int(np.sum((np.array([p.score for p in props]) > 0) != y)) for props, y in items)
        return errs / max(sum(len(y) for _, y in items), 1)
    outs = run_tasks(_predict, list(items), client=client, label="S-SVM training error", extra_args=(weights, settings))
    return sum(o["errors"] for o in outs) / max(total or sum(o["nodes"] for o in outs), 1)


def train_crf(proposals_per_space: Sequence[Sequence[Proposal]],
              ground_truth_per_space: Sequence[Sequence[dict[str, Any]]], *, grid: int | None = None,
              k: int | dict[str, int] | None = None, lam: float | None = None, iterations: int | None = None,
              tol: float | None = None, miss_cost: float | None = None, iou_threshold: float | None = None,
              buildings: Sequence[Any] | None = None, miss_costs: Sequence[float] | None = None,
              client=None, settings: CRFSettings | None = None,
              report: dict[str, Any] | None = None) -> CRFWeights:
    """Learn :class:`engine.crf.model.CRFWeights` from detected proposals and ground-truth boxes, space by space.

    Parameters
    ----------
    proposals_per_space
        The detector's proposals of each training space (one list per space).
    ground_truth_per_space
        The ground-truth element records (``class_code``, ``center``, ``size``, ``yaw``) of the same spaces.
    grid
        ``K`` of the occupancy patterns; None takes it from the proposals.
    k
        ``k_e`` (one number or ``{class: k}``); None reads ``buildingparser.crf.k`` / ``k-per-class``.
    lam, iterations, tol, client, settings
        See :func:`fit_ssvm`.
    miss_cost
        One miss cost (see :func:`fit_ssvm`); None: chosen among ``miss_costs`` when there are folds,
        else ``buildingparser.crf.ssvm.miss-cost``.
    iou_threshold
        Matching threshold of the labels; None reads ``buildingparser.crf.ssvm.iou``.
    buildings
        The building of each space.  Given (and at least two buildings), the miss cost among the
        candidates and the classes the CRF decides are chosen by building-wise folds
        (:func:`engine.crf.validation.choose`); None or one building: ``miss_cost``, every class decided.
        The weights are learnt with every class free either way (as in the folds); the returned
        :attr:`~engine.crf.model.CRFWeights.decides` says where they decide when used.
    miss_costs
        Candidates when ``miss_cost`` is None; None reads ``buildingparser.crf.train.miss-costs``.
    report
        If given, filled with ``history``, ``errors``, ``objective``, ``converged``, ``statuses`` (see
        :class:`SSVMResult`), ``spaces`` and ``positives`` / ``proposals`` (label counts), ``miss_cost``
        and ``validation`` (the choice's report, or None).
    """
    if len(proposals_per_space) != len(ground_truth_per_space):
        raise ValueError("one ground-truth list per space of proposals expected")
    if buildings is not None and len(buildings) != len(proposals_per_space):
        raise ValueError("one building label per space expected")
    iou = float(config.setting("crf.ssvm.iou") if iou_threshold is None else iou_threshold)
    if grid is None:
        grid = _grid_of(proposals_per_space)
    default, costs = _miss_costs(miss_cost, miss_costs)
    jobs = [(list(p), list(g)) for p, g in zip(proposals_per_space, ground_truth_per_space)]
    labels = label_spaces([p for p, _ in jobs], [g for _, g in jobs], iou, client=client)
    init = CRFWeights.new(grid, k=k)
    fit_kw = dict(lam=lam, iterations=iterations, tol=tol, client=client, settings=settings)
    validation = None
    cost = default
    if buildings is not None:
        chosen, decides, validation = choose(
            [p for p, _ in jobs], [g for _, g in jobs], labels, list(buildings), costs, init,
            lambda ex, w, c: fit_ssvm(ex, w, miss_cost=c, **fit_kw).weights, client=client, settings=settings,
            iou=iou)
        cost = default if chosen is None else chosen
    # every class free, as in the folds that chose the gate; the gate applies when the weights are used
    res = fit_ssvm([(p, y) for (p, _), y in zip(jobs, labels)], init, miss_cost=cost, **fit_kw)
    if validation is not None:
        res.weights.decides = decides
    if report is not None:
        report.update(history=res.history, errors=res.errors, objective=res.objective, converged=res.converged,
                      statuses=res.statuses,
                      spaces=sum(1 for p, _ in jobs if p), positives=int(sum(int(y.sum()) for y in labels)),
                      proposals=int(sum(len(y) for y in labels)), miss_cost=cost, validation=validation)
    return res.weights


def _grid_of(proposals_per_space: Sequence[Sequence[Proposal]]) -> int:
    """``K`` of the occupancy patterns of the first proposal."""
    first = next((p for props in proposals_per_space for p in props), None)
    if first is None:
        raise ValueError("no proposals to train on")
    return int(np.asarray(first.occupancy).shape[0])


def _miss_costs(miss_cost: float | None, miss_costs: Sequence[float] | None) -> tuple[float, list[float]]:
    """The default miss cost and the candidates to choose from (only ``miss_cost`` when it is given)."""
    default = float(config.setting("crf.ssvm.miss-cost") if miss_cost is None else miss_cost)
    costs = [default] if miss_cost is not None else [float(c) for c in (
        miss_costs if miss_costs is not None else config.setting("crf.train.miss-costs") or [default])]
    return default, costs
