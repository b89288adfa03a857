"""Contextual consistency (paper 4.1): choose the final elements of each space with a CRF.

The proposals of one space are the nodes of a graph; each node ``v`` is joined to
its ``k_e`` nearest proposals of every class ``e`` (distance between the centres
``P + S/2`` of the boxes in the space's unit cube; ties broken by proposal order;
an edge found from both ends is one edge).  A binary label ``y_v`` says whether
proposal ``v`` is kept, and the kept set maximises equation (1) of the paper::

    E(y) = sum_v (w0 * l_v + b_{c(v)}) y_v + sum_{(u,v) in E} y_u y_v (w_{c(u),c(v)} . Phi_uv)

written as the integer program (2) with one auxiliary ``y_uv`` per edge and the
constraints ``y_uv <= y_u``, ``y_uv <= y_v``, ``y_u + y_v <= y_uv + 1`` (so
``y_uv = y_u y_v``), solved exactly with OR-Tools CP-SAT.  Only the constraints
the objective can press on are posted (the standard reduction: the upper bounds
for an edge of positive energy, the lower bound for a negative one); at an
optimum ``y_uv = y_u y_v`` still holds for every edge, the optimum is the same,
and CP-SAT solves it about 1.5x faster.

Choices made here, beyond the paper's text:

* **Unary term.** ``w0 * l_v`` from the detector's score ``l_v`` (the SVM's, or the
  log-odds of the model's learned re-ranking for the classes it is used for,
  :mod:`engine.detection.rescore`) plus a bias ``b_c`` per class (the paper has ``w0`` only),
  so the CRF can learn a threshold per class.
* **Edge features.** ``Phi_uv = [B_u, B_v, S_u, S_v, |P_u - P_v|, 1, IoU_uv]``:
  the paper's occupancy patterns (flattened K^3, scaled by ``1/sqrt(K^3)`` so
  that each block has norm at most 1), sizes and absolute position difference in
  the unit cube, then two additions: a constant (a linear function of
  ``|P_u - P_v|`` alone cannot penalise close pairs without also rewarding far
  ones; the constant lets it pay off at a learned distance) and the unit-cube
  IoU of the two boxes (what duplicates look like).  Every ``Phi_uv`` is
  divided by ``sum_e k_e`` (:func:`edge_scale`), so that a node's pairwise
  terms add up to a mean over its neighbours, on the scale of its unary term,
  rather than a sum; a constant factor, so the model is the same, but the
  S-SVM (:mod:`engine.crf.ssvm`) is far better conditioned.
* **Edge weights are indexed per unordered class pair** ``{c(u), c(v)}``: 12
  classes give 78 weight vectors.  The edge is oriented so that ``u`` has the
  smaller class code; for a same-class pair the two halves are symmetrised
  (``(B_u + B_v)/2`` in both B slots, likewise S) so that the energy does not
  depend on which end is called ``u``.
* **Bounded graphs.** Only the ``max-nodes-per-class`` best-scored proposals of
  each class (default 40) get edges; the others, and every node left without an
  edge, are kept exactly when their unary term is positive (that is their
  optimal label: they touch no edge).  A space's IP thus has at most
  ``12 * N`` node and ``12 * N * sum_e k_e`` edge variables.
* **Classes the CRF decides** (:attr:`CRFWeights.decides`, chosen by
  :mod:`engine.crf.validation` on the CRF's training buildings, out of fold): the
  nodes of the other classes keep the detector's decision (score > 0) and enter the
  program with fixed labels (:func:`fix_labels`), as context for the others.
* **Integer objective.** CP-SAT needs integer coefficients: every unary and
  pairwise energy is multiplied by ``resolution / max|energy|`` (``resolution``
  = 10^6 by default) and rounded.  The solution is optimal for the rounded
  problem, hence within ``(n + m) / 2`` units, i.e. ``(n + m) / 2 * max|energy| / 10^6``,
  of the true optimum; coefficients that round to 0 are left out.
* **Determinism.** One search worker, ``linearization_level = 2`` (measured in
  ``benchmarks/bench_crf.py``: it proves optimality of thousands of variables in
  well under a second where the default settings may not finish in a minute), a
  fixed ``random_seed``, a deterministic-time budget and a wall-clock safety net.
  While the solver proves optimality or stops on the deterministic budget the
  result is reproducible; if the wall-clock limit fires first, the status says so.
  ``FEASIBLE`` (a limit was reached) keeps the best solution found and warns; no
  solution at all falls back to the unary-only labels and warns.

Besides the kept set, every proposal gets a *contextual score*, the energy its
keeping adds with the other labels fixed (:func:`flip_margins`, stored in
``Proposal.extra["crf_margin"]``; at the optimum >= 0 for the kept ones and <= 0
for the dropped ones, up to the integer rounding of the solve).  Average
precision scores a ranked list, and a selection can only lose recall, so the
benchmark (``benchmarks/bench_crf.py``) reports both: the AP of all proposals
ranked by this score against the detector's own ranking, and the final set's
AP, precision and recall against the detector's own decision (score > 0).

Settings: ``buildingparser.crf.*`` (``engine/crf/crf.yaml``).  The weights live in a
:class:`CRFWeights` (arrays + JSON parameters, never pickle).
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
import statistics
import time
import warnings
from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np

from engine import config
from engine.detection.proposals import Proposal
from tiles.classes import ELEMENT_CLASSES
from tiles.tasks import run_tasks

#: Classes that take part in the CRF (the 12 element classes; clutter is not an element).
N_CLASSES = len(ELEMENT_CLASSES)
#: Unordered class pairs ``(a, b)``, ``a <= b``, in the order of :attr:`CRFWeights.edge`'s rows.
CLASS_PAIRS: tuple[tuple[int, int], ...] = tuple((a, b) for a in range(N_CLASSES) for b in range(a, N_CLASSES))
_PAIR_INDEX = np.zeros((N_CLASSES, N_CLASSES), dtype=np.int64)
for _i, (_a, _b) in enumerate(CLASS_PAIRS):
    _PAIR_INDEX[_a, _b] = _PAIR_INDEX[_b, _a] = _i

#: Key of ``Proposal.extra`` where the CRF leaves each proposal's contextual score (:func:`flip_margins`).
MARGIN = "crf_margin"
FORMAT = "buildingparser-crf"
#: 2: the per-class ``decides`` mask (``crf_decides``); version-1 weights load with every class decided.
FORMAT_VERSION = 2
#: Names of the blocks of one edge feature vector, in order (see the module docstring).
EDGE_FEATURE_BLOCKS = ("B_u", "B_v", "S_u", "S_v", "abs_dP", "const", "iou")


def pair_index(a: int, b: int) -> int:
    """Row of :attr:`CRFWeights.edge` that weighs edges between classes ``a`` and ``b`` (either order)."""
    return int(_PAIR_INDEX[a, b])


def edge_feature_size(grid: int) -> int:
    """Length of ``Phi_uv`` for a ``grid``^3 occupancy pattern: 2 K^3 + 3 + 3 + 3 + 1 + 1."""
    return 2 * grid ** 3 + 11


# -----------------------------------------------------------------------------------------
# Weights
# -----------------------------------------------------------------------------------------
@dataclass
class CRFWeights:
    """The CRF's parameters: ``w0``, a bias per class, a weight vector per unordered class pair.

    Parameters
    ----------
    w0
        Weight of the detector's score in the unary term.
    bias
        ``(12,)`` per-class unary bias ``b_c``.
    edge
        ``(78, 2 K^3 + 11)`` pairwise weights, row :func:`pair_index` ``(a, b)``.
    grid
        ``K``, the side of the occupancy pattern the edge features were built for.
    k
        ``(12,)`` neighbours per class ``k_e`` of the graph these weights were trained on.
    decides
        ``(12,)`` bool: the classes whose keep/drop the CRF decides.  A class it does not decide
        keeps the detector's own decision (score > 0) and takes part only as context: its labels
        are fixed in the integer program (:func:`fix_labels`).  ``train-crf`` keeps only the classes
        whose out-of-fold kept set beats the detector's own set (:mod:`engine.crf.validation`).
        None: every class.
    """

    w0: float
    bias: np.ndarray
    edge: np.ndarray
    grid: int
    k: np.ndarray
    decides: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.w0 = float(self.w0)
        self.grid = int(self.grid)
        self.bias = np.asarray(self.bias, dtype=np.float64).reshape(-1)
        self.edge = np.asarray(self.edge, dtype=np.float64)
        self.k = np.asarray(self.k, dtype=np.int64).reshape(-1)
        self.decides = (np.ones(N_CLASSES, dtype=bool) if self.decides is None
                        else np.asarray(self.decides, dtype=bool).reshape(-1))
        if self.decides.shape != (N_CLASSES,):
            raise ValueError(f"decides needs {N_CLASSES} values, got {self.decides.shape}")
        if self.grid < 1:
            raise ValueError(f"grid must be >= 1, not {self.grid}")
        if self.bias.shape != (N_CLASSES,) or self.k.shape != (N_CLASSES,):
            raise ValueError(f"bias and k need {N_CLASSES} values, got {self.bias.shape} and {self.k.shape}")
        want = (len(CLASS_PAIRS), edge_feature_size(self.grid))
        if self.edge.shape != want:
            raise ValueError(f"edge weights of shape {self.edge.shape}, expected {want} for grid {self.grid}")
        if np.any(self.k < 0):
            raise ValueError("k_e must be >= 0")
        if not (math.isfinite(self.w0) and np.all(np.isfinite(self.bias)) and np.all(np.isfinite(self.edge))):
            raise ValueError("CRF weights must be finite")

    # -- construction ----------------------------------------------------------------------
    @classmethod
    def new(cls, grid: int, *, k: int | dict[str, int] | None = None, w0: float = 1.0) -> "CRFWeights":
        """Untrained weights: ``w0`` on the score, no bias, no pairwise terms (keeps positive scores).

        ``k`` is one ``k_e`` for all classes, or ``{class name: k_e}`` overrides of
        ``buildingparser.crf.k``; None reads ``buildingparser.crf.k`` and ``k-per-class``.
        """
        ks = default_k() if k is None else (
            np.full(N_CLASSES, int(k)) if isinstance(k, (int, np.integer)) else default_k(k))
        return cls(w0, np.zeros(N_CLASSES), np.zeros((len(CLASS_PAIRS), edge_feature_size(grid))), grid, ks)

    @property
    def size(self) -> int:
        """Length of :meth:`vector`."""
        return 1 + N_CLASSES + self.edge.size

    def vector(self) -> np.ndarray:
        """All weights as one vector ``[w0, bias, edge.ravel()]`` (the layout of :func:`joint_feature`)."""
        return np.concatenate([[self.w0], self.bias, self.edge.ravel()])

    def with_vector(self, vec: np.ndarray) -> "CRFWeights":
        """Weights of the same shape (grid, k) from a :meth:`vector`."""
        vec = np.asarray(vec, dtype=np.float64)
        if vec.shape != (self.size,):
            raise ValueError(f"weight vector of shape {vec.shape}, expected ({self.size},)")
        return CRFWeights(vec[0], vec[1:1 + N_CLASSES], vec[1 + N_CLASSES:].reshape(self.edge.shape),
                          self.grid, self.k.copy(), self.decides.copy())

    # -- storage: arrays + JSON, never pickle ------------------------------------------------
    def to_arrays(self, prefix: str = "crf_") -> dict[str, np.ndarray]:
        """The arrays to store in a model ``.npz`` (names prefixed ``crf_``)."""
        return {f"{prefix}bias": self.bias.copy(), f"{prefix}edge": self.edge.copy(), f"{prefix}k": self.k.copy(),
                f"{prefix}decides": self.decides.copy()}

    def params(self) -> dict[str, Any]:
        """The JSON parameters stored next to :meth:`to_arrays`."""
        return {"format": FORMAT, "version": FORMAT_VERSION, "w0": self.w0, "grid": self.grid,
                "classes": list(ELEMENT_CLASSES), "edge_features": list(EDGE_FEATURE_BLOCKS),
                "edge_index": "unordered class pair (a <= b), row-major over a then b",
                "decides": [c for c, d in zip(ELEMENT_CLASSES, self.decides) if d]}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], params: dict[str, Any], prefix: str = "crf_") -> "CRFWeights":
        """Weights back from :meth:`to_arrays` and :meth:`params`; a clear error for a foreign file."""
        if params.get("format") != FORMAT:
            raise ValueError(f"not CRF weights (format {params.get('format')!r}, expected {FORMAT!r})")
        if int(params.get("version", 0)) > FORMAT_VERSION:
            raise ValueError(f"CRF weights of version {params.get('version')}: upgrade buildingparser")
        if list(params.get("classes", [])) != list(ELEMENT_CLASSES):
            raise ValueError("CRF weights were trained for other classes")
        try:
            return cls(params["w0"], arrays[f"{prefix}bias"], arrays[f"{prefix}edge"], params["grid"],
                       arrays[f"{prefix}k"], arrays.get(f"{prefix}decides"))
        except KeyError as exc:
            raise ValueError(f"CRF weights lack {exc}") from None

    def save(self, path: str | os.PathLike) -> tuple[str, str]:
        """Write ``<path>.npz`` and ``<path>.json`` (a ``.npz``/``.json`` suffix of ``path`` is dropped)."""
        stem = _stem(path)
        np.savez(stem + ".npz", **self.to_arrays())
        with open(stem + ".json", "w") as f:
            json.dump(self.params(), f, indent=1)
        return stem + ".npz", stem + ".json"

    @classmethod
    def load(cls, path: str | os.PathLike) -> "CRFWeights":
        """Read weights written by :meth:`save`."""
        stem = _stem(path)
        with open(stem + ".json") as f:
            params = json.load(f)
        with np.load(stem + ".npz", allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        return cls.from_arrays(arrays, params)

    # -- the detection model's slot ----------------------------------------------------------
    def store_in(self, model: Any, training: dict[str, Any] | None = None) -> None:
        """Put these weights in a detection :class:`engine.detection.model.Model` (its ``crf`` / ``crf_arrays`` slot).

        ``training`` (JSON-able: data, spaces, S-SVM iterations, errors...) is kept under
        ``model.crf["training"]`` as the weights' provenance; it is not needed to use them.
        """
        model.crf = self.params()
        if training is not None:
            model.crf["training"] = training
        model.crf_arrays = self.to_arrays()

    @classmethod
    def from_model(cls, model: Any) -> "CRFWeights | None":
        """The weights stored in a detection model, or None when it has none."""
        if not getattr(model, "crf", None):
            return None
        return cls.from_arrays(model.crf_arrays, model.crf)

    # -- convenience for hand-set weights ------------------------------------------------------
    def block(self, a: int, b: int, name: str) -> np.ndarray:
        """A writable view of one block (see :data:`EDGE_FEATURE_BLOCKS`) of the weights of pair ``{a, b}``."""
        k3 = self.grid ** 3
        spans = {"B_u": (0, k3), "B_v": (k3, 2 * k3), "S_u": (2 * k3, 2 * k3 + 3), "S_v": (2 * k3 + 3, 2 * k3 + 6),
                 "abs_dP": (2 * k3 + 6, 2 * k3 + 9), "const": (2 * k3 + 9, 2 * k3 + 10),
                 "iou": (2 * k3 + 10, 2 * k3 + 11)}
        lo, hi = spans[name]
        return self.edge[pair_index(a, b), lo:hi]


def _stem(path: str | os.PathLike) -> str:
    p = os.fspath(path)
    for suffix in (".npz", ".json"):
        if p.endswith(suffix):
            return p[: -len(suffix)]
    return p


def default_k(overrides: dict[str, int] | None = None) -> np.ndarray:
    """``k_e`` per class from ``buildingparser.crf.k`` and ``k-per-class`` (or the given overrides)."""
    base = int(config.get("crf.k", 3))
    per = dict(config.get("crf.k-per-class", {}) or {}) if overrides is None else dict(overrides)
    unknown = set(per) - set(ELEMENT_CLASSES)
    if unknown:
        raise ValueError(f"k-per-class names unknown classes {sorted(unknown)}")
    ks = np.full(N_CLASSES, base, dtype=np.int64)
    for name, v in per.items():
        ks[ELEMENT_CLASSES.index(name)] = int(v)
    if np.any(ks < 0):
        raise ValueError("k_e must be >= 0")
    return ks


# -----------------------------------------------------------------------------------------
# Settings
# -----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CRFSettings:
    """How the CRF of one space is bounded and solved (read on the driver, sent to the tasks)."""

    max_nodes_per_class: int = 40
    seed: int = 0
    linearization_level: int = 2
    deterministic_time: float = 20.0
    time_limit: float = 30.0
    resolution: int = 1_000_000

    def __post_init__(self) -> None:
        if self.max_nodes_per_class < 1:
            raise ValueError(f"max-nodes-per-class must be >= 1, not {self.max_nodes_per_class}")
        if self.linearization_level not in (0, 1, 2):
            raise ValueError(f"linearization-level must be 0, 1 or 2, not {self.linearization_level}")
        if not (self.deterministic_time > 0 and self.time_limit > 0):
            raise ValueError("deterministic-time and time-limit must be positive")
        if not 1 <= self.resolution <= 2 ** 40:
            raise ValueError(f"objective-resolution must be in [1, 2^40], not {self.resolution}")

    @classmethod
    def from_config(cls, **overrides: Any) -> "CRFSettings":
        """``buildingparser.crf.*`` settings, with keyword overrides (None = use the setting)."""
        vals = {"max_nodes_per_class": int(config.get("crf.max-nodes-per-class", 40)),
                "seed": int(config.get("crf.seed", 0)),
                "linearization_level": int(config.get("crf.linearization-level", 2)),
                "deterministic_time": float(config.get("crf.deterministic-time", 20.0)),
                "time_limit": float(config.get("crf.time-limit", 30.0)),
                "resolution": int(config.get("crf.objective-resolution", 1_000_000))}
        vals.update({k: v for k, v in overrides.items() if v is not None})
        return cls(**vals)


# -----------------------------------------------------------------------------------------
# The graph of one space
# -----------------------------------------------------------------------------------------
@dataclass
class CRFGraph:
    """Nodes (proposals) and edges of one space's CRF with their features.

    ``edges[i] = (u, v)`` with ``class[u] <= class[v]`` (see the module docstring),
    ``pairs[i]`` the class-pair row of the weights, ``phi[i]`` the edge features.
    """

    classes: np.ndarray  # (n,) int
    scores: np.ndarray  # (n,) float
    edges: np.ndarray  # (m, 2) int
    pairs: np.ndarray  # (m,) int
    phi: np.ndarray  # (m, D) float
    grid: int

    @property
    def n(self) -> int:
        return len(self.classes)

    @property
    def m(self) -> int:
        return len(self.edges)


def _proposal_arrays(proposals: list[Proposal], grid: int) -> tuple[np.ndarray, ...]:
    n = len(proposals)
    cls = np.fromiter((p.class_code for p in proposals), dtype=np.int64, count=n)
    if n and (cls.min() < 0 or cls.max() >= N_CLASSES):
        raise ValueError(f"proposal classes must be element classes 0..{N_CLASSES - 1}, got {sorted(set(cls))}")
    score = np.fromiter((p.score for p in proposals), dtype=np.float64, count=n)
    if not np.all(np.isfinite(score)):
        raise ValueError("proposal scores must be finite")
    pos = np.array([np.asarray(p.position, dtype=np.float64).reshape(3) for p in proposals]).reshape(n, 3)
    size = np.array([np.asarray(p.size, dtype=np.float64).reshape(3) for p in proposals]).reshape(n, 3)
    k3 = grid ** 3
    occ = np.zeros((n, k3), dtype=np.float64)
    for i, p in enumerate(proposals):
        b = np.asarray(p.occupancy)
        if b.shape != (grid, grid, grid):
            raise ValueError(f"proposal {i}: occupancy of shape {b.shape}, the CRF weights expect {(grid,) * 3}")
        occ[i] = b.reshape(-1).astype(bool)
    return cls, score, pos, size, occ


def _graph_nodes(cls: np.ndarray, score: np.ndarray, max_per_class: int) -> np.ndarray:
    """Mask of the nodes that get edges: the best-scored ``max_per_class`` of each class (ties: first)."""
    inside = np.zeros(len(cls), dtype=bool)
    for c in np.unique(cls):
        idx = np.flatnonzero(cls == c)
        order = idx[np.argsort(-score[idx], kind="stable")]
        inside[order[:max_per_class]] = True
    return inside


def build_graph(proposals: list[Proposal], k: np.ndarray, grid: int, *, max_nodes_per_class: int = 40) -> CRFGraph:
    """The CRF graph of one space: k_e-nearest-neighbour edges per class and their features.

    Parameters
    ----------
    proposals
        The proposals of one space (unit-cube ``position``, ``size``, ``occupancy``).
    k
        ``(12,)`` neighbours per class.
    grid
        ``K`` of the occupancy patterns.
    max_nodes_per_class
        Only this many best-scored proposals per class get edges (the graph bound).
    """
    k = np.asarray(k, dtype=np.int64)
    cls, score, pos, size, occ = _proposal_arrays(proposals, grid)
    n = len(cls)
    d = edge_feature_size(grid)
    empty = CRFGraph(cls, score, np.zeros((0, 2), np.int64), np.zeros(0, np.int64), np.zeros((0, d)), grid)
    if n < 2:
        return empty
    inside = np.flatnonzero(_graph_nodes(cls, score, max_nodes_per_class))
    centre = pos[inside] + size[inside] / 2
    dist = np.sqrt(((centre[:, None, :] - centre[None, :, :]) ** 2).sum(-1))
    np.fill_diagonal(dist, np.inf)
    ccls = cls[inside]
    us, vs = [], []
    for e in np.unique(ccls):
        ke = int(k[e])
        cols = np.flatnonzero(ccls == e)
        ke = min(ke, len(cols))
        if ke == 0:
            continue
        sub = dist[:, cols]
        order = np.argsort(sub, axis=1, kind="stable")[:, :ke]
        ok = np.isfinite(np.take_along_axis(sub, order, axis=1))
        us.append(np.repeat(np.arange(len(inside)), ke)[ok.ravel()])
        vs.append(cols[order].ravel()[ok.ravel()])
    if not us:
        return empty
    u, v = inside[np.concatenate(us)], inside[np.concatenate(vs)]
    # orient every edge so that u has the smaller class (then the smaller index); dedupe
    swap = (cls[u] > cls[v]) | ((cls[u] == cls[v]) & (u > v))
    u, v = np.where(swap, v, u), np.where(swap, u, v)
    edges = np.unique(np.stack([u, v], axis=1), axis=0)
    u, v = edges[:, 0], edges[:, 1]
    pairs = _PAIR_INDEX[cls[u], cls[v]]
    k3 = grid ** 3
    scale_b = 1.0 / math.sqrt(k3)
    bu, bv = occ[u] * scale_b, occ[v] * scale_b
    su, sv = size[u], size[v]
    same = cls[u] == cls[v]
    if np.any(same):
        bm = (bu[same] + bv[same]) / 2
        sm = (su[same] + sv[same]) / 2
        bu[same], bv[same], su[same], sv[same] = bm, bm, sm, sm
    phi = np.concatenate([bu, bv, su, sv, np.abs(pos[u] - pos[v]), np.ones((len(u), 1)),
                          box_iou_unit(pos[u], size[u], pos[v], size[v])[:, None]], axis=1)
    phi /= edge_scale(k)
    return CRFGraph(cls, score, edges.astype(np.int64), pairs, phi, grid)


def edge_scale(k: np.ndarray) -> float:
    """What every edge feature vector is divided by: ``sum_e k_e`` (at least 1)."""
    return float(max(1, int(np.sum(k))))


def box_iou_unit(p1: np.ndarray, s1: np.ndarray, p2: np.ndarray, s2: np.ndarray) -> np.ndarray:
    """IoU of axis-aligned boxes ``[P, P + S]`` (rows), in the unit cube of a space."""
    lo = np.maximum(p1, p2)
    hi = np.minimum(p1 + s1, p2 + s2)
    inter = np.prod(np.clip(hi - lo, 0, None), axis=-1)
    union = np.prod(s1, axis=-1) + np.prod(s2, axis=-1) - inter
    return np.divide(inter, union, out=np.zeros_like(inter), where=union > 0)


def energies(graph: CRFGraph, weights: CRFWeights) -> tuple[np.ndarray, np.ndarray]:
    """Unary ``w0 l_v + b_c`` per node and pairwise ``w_{c(u)c(v)} . Phi_uv`` per edge."""
    if graph.grid != weights.grid:
        raise ValueError(f"graph built for grid {graph.grid}, weights for grid {weights.grid}")
    unary = weights.w0 * graph.scores + weights.bias[graph.classes]
    pairwise = np.einsum("md,md->m", weights.edge[graph.pairs], graph.phi) if graph.m else np.zeros(0)
    return unary, pairwise


def joint_feature(graph: CRFGraph, y: np.ndarray) -> np.ndarray:
    """``Psi(x, y)``: the energy of labels ``y`` is ``weights.vector() @ joint_feature(graph, y)``."""
    y = np.asarray(y, dtype=bool)
    out = np.zeros(1 + N_CLASSES + len(CLASS_PAIRS) * edge_feature_size(graph.grid))
    out[0] = float(graph.scores @ y)
    out[1:1 + N_CLASSES] = np.bincount(graph.classes, weights=y.astype(float), minlength=N_CLASSES)
    if graph.m:
        on = y[graph.edges[:, 0]] & y[graph.edges[:, 1]]
        edge = np.zeros((len(CLASS_PAIRS), graph.phi.shape[1]))
        np.add.at(edge, graph.pairs[on], graph.phi[on])
        out[1 + N_CLASSES:] = edge.ravel()
    return out


def energy(unary: np.ndarray, edges: np.ndarray, pairwise: np.ndarray, y: np.ndarray) -> float:
    """Equation (1) for labels ``y``."""
    y = np.asarray(y, dtype=bool)
    total = float(unary[y].sum())
    if len(edges):
        total += float(pairwise[y[edges[:, 0]] & y[edges[:, 1]]].sum())
    return total


# -----------------------------------------------------------------------------------------
# The integer program
# -----------------------------------------------------------------------------------------
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
    solver = cp_model.CpSolver()
    p = solver.parameters
    p.num_workers = 1
    p.linearization_level = settings.linearization_level
    p.random_seed = settings.seed
    p.max_deterministic_time = settings.deterministic_time
    p.max_time_in_seconds = settings.time_limit
    p.log_search_progress = False
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


def fixed_labels(graph: CRFGraph, weights: CRFWeights) -> np.ndarray | None:
    """Per node: 1/0 for the nodes of classes the CRF does not decide (the detector's score > 0), -1 for
    the free ones; None when the CRF decides every node."""
    fixed = ~weights.decides[graph.classes]
    if not fixed.any():
        return None
    return np.where(fixed, (graph.scores > 0).astype(np.int64), -1)


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


# -----------------------------------------------------------------------------------------
# Public API: one space, all spaces
# -----------------------------------------------------------------------------------------
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
    keep, margin, info = _select(proposals, weights, settings)
    if info["warning"]:
        warnings.warn(info["warning"], RuntimeWarning, stacklevel=2)
    for p, m in zip(proposals, margin):
        p.extra[MARGIN] = float(m)
    return [p for p, k in zip(proposals, keep) if k], info


def _select(proposals: list[Proposal], weights: CRFWeights,
            settings: CRFSettings | None) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """:func:`select_elements` without side effects: keep mask, margins, info."""
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
    y, sinfo = solve_fixed(unary, graph.edges, pairwise, fixed_labels(graph, weights), settings)
    warning = f"space {sid}: {sinfo['warning']}" if sinfo["warning"] else None
    info = {"space_id": sid, "status": sinfo["status"], "seconds": time.perf_counter() - t0,
            "solver_seconds": sinfo["seconds"], "nodes": graph.n, "edges": graph.m, "kept": int(y.sum()),
            "objective": sinfo["objective"], "warning": warning}
    return y, flip_margins(unary, graph.edges, pairwise, y), info


def _crf_task(group: list[Proposal], weights: CRFWeights,
              settings: CRFSettings) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """One space's task: keep mask and margins of ``group``, and the info (the driver issues the warnings)."""
    return _select(group, weights, settings)


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
        "decides": [class, ...], "per_space": [info, ...]}`` (``solve_seconds`` is graph building +
        solving, per space; ``decides``: the classes whose keep/drop the CRF decided, the others kept
        the detector's decision).
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
    done = run_tasks(_crf_task, [items[k] for k in order], client=client, label="CRF per space",
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
              "decides": [c for c, d in zip(ELEMENT_CLASSES, weights.decides) if d], "per_space": infos}
    return [p for p, k in zip(proposals, keep) if k], report


def metrics_block(report: dict[str, Any]) -> dict[str, Any]:
    """The ``crf`` block of ``metrics.json`` from an :func:`apply_crf` report (without the per-space details)."""
    return {k: report[k] for k in ("spaces", "solve_seconds", "status", "proposals", "kept", "decides")
            if k in report}
