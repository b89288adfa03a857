"""The CRF graph of one space (paper 4.1): k_e-nearest-neighbour edges, their features, the energies.

Each proposal is joined to its ``k_e`` nearest proposals of every class; an edge carries
``Phi_uv = [B_u, B_v, S_u, S_v, |P_u - P_v|, 1, IoU_uv] / sum_e k_e``.  :func:`energies` gives the
unary and pairwise terms of equation (1), :func:`joint_feature` the same energy as a linear function
of the weights (for the structured SVM).  Design notes: ``docs/design/crf.md``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from engine.crf.model import CLASS_PAIRS, N_CLASSES, PAIR_INDEX, CRFWeights, edge_feature_size
from engine.detection.proposals import Proposal


@dataclass
class CRFGraph:
    """Nodes (proposals) and edges of one space's CRF with their features.

    ``edges[i] = (u, v)`` with ``class[u] <= class[v]`` (see ``docs/design/crf.md``),
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
    pairs = PAIR_INDEX[cls[u], cls[v]]
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
