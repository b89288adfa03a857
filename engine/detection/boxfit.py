"""Learned box prediction: each detection's faces moved by a per-class regression on the points around it.

The bounding-box prediction of deformable part models (Felzenszwalb et al.,
2010), here on point statistics.  A sliding window sits on the voxel grid and
has one of a few sizes per class: a 10 cm deep board window lands up to half a
voxel off the board, a 1.4 m window on a 2.3 m board covers 60 % of it, and
both miss IoU 0.5.  Per detection and axis, the points of its box grown by its
own size on both sides along that axis (the box's extent on the other two
axes) describe where the element stops: quantiles and a density profile of
their coordinate, relative to the box.  Per class, axis role (the thinner
horizontal axis, the wider one, height) and face, a ridge regression learnt on
the training buildings' own detections predicts the offset of the
ground-truth face.  Horizontal axes are mirrored so that the face towards the
space's nearer end comes first (a board's back is the wall, wherever the wall
is).  Each axis role of a class is used only when leave-one-building-out
validation on those detections says that it brings clearly more of them to
IoU >= 0.5 than it takes away (:func:`fit_boxfit`, which chooses the ridge
penalty the same way).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tiles.classes import ELEMENT_CLASSES

N_CLASSES = len(ELEMENT_CLASSES)
#: Quantiles of the points' coordinate (relative to the box) among the features.
QUANTILES = (0.02, 0.1, 0.25, 0.5, 0.75, 0.9, 0.98)
#: Density-profile bins over the grown slab [-GROW, 1 + GROW] (box-relative).
BINS = 12
#: The box is grown by this many times its size on both sides of the axis.
GROW = 1.0
#: Edges of the density profile's bins (as ``np.histogram(u, BINS, (-GROW, 1 + GROW))``).
PROFILE_EDGES = np.linspace(-GROW, 1.0 + GROW, BINS + 1)
#: Features per axis: quantiles, profile, log size (metres), share of the slab inside the box, empty flag.
N_FEATURES = len(QUANTILES) + BINS + 3
#: Ridge penalties tried by the leave-one-building-out validation (on standardised features).
ALPHAS = (10.0, 100.0, 1000.0)
#: Fewest matched detections and buildings for a class to get a regression.
MIN_SAMPLES, MIN_BUILDINGS = 8, 3


def axis_roles(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Per box ``(n, 3)``, the axis of each role: thinner horizontal, wider horizontal, vertical."""
    size = hi - lo
    thin_x = size[:, 0] <= size[:, 1]
    return np.stack([np.where(thin_x, 0, 1), np.where(thin_x, 1, 0), np.full(len(lo), 2)], axis=1)


def _mirrored(lo: np.ndarray, hi: np.ndarray, extent: np.ndarray) -> np.ndarray:
    """Per box and axis, whether the axis is read backwards (horizontal, box centre past the middle)."""
    m = (lo + hi) / 2.0 > np.broadcast_to(extent, lo.shape) / 2.0
    m[:, 2] = False
    return m


#: :data:`QUANTILES` as an array (for :func:`sorted_quantiles`).
_Q = np.asarray(QUANTILES, dtype=np.float64)


def sorted_quantiles(u: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``np.quantile(u, q)`` (its default, linear method) of values ``u`` already sorted: bit for bit the same.

    numpy partitions its input again on every call (a quarter of the box features' time);
    here the order statistics are read off the sorted values with numpy's own index and
    interpolation arithmetic (the linear method's virtual index, ``_get_indexes``, ``_lerp``).
    """
    n = len(u)
    virtual = (n - 1) * q
    prev = np.floor(virtual)
    nxt = prev + 1.0
    above, below = virtual >= n - 1, virtual < 0
    prev[above], nxt[above] = -1.0, -1.0
    prev[below], nxt[below] = 0.0, 0.0
    gamma = virtual - prev
    a, b = u[prev.astype(np.intp)], u[nxt.astype(np.intp)]
    diff = b - a
    out = a + diff * gamma
    np.subtract(b, diff * (1.0 - gamma), out=out, where=gamma >= 0.5)
    return out


def axis_features(points: np.ndarray, lo: np.ndarray, hi: np.ndarray, axis: int, mirror: bool,
                  within: np.ndarray | None = None) -> np.ndarray:
    """Features ``(N_FEATURES,)`` of one box along one axis from ``points`` (canonical metres) around it.

    ``points`` may hold more than the slab (the box grown along every axis): only those
    within the box on the other two axes and within the grown slab on ``axis`` count.
    ``within``: ``(points >= lo) & (points <= hi)`` per axis, if already computed.
    """
    other = [a for a in range(3) if a != axis]
    s = max(hi[axis] - lo[axis], 1e-6)
    x = points[:, axis]
    if within is None:
        within = (points >= lo) & (points <= hi)
    ok = within[:, other[0]] & within[:, other[1]]
    u = (x[ok] - lo[axis]) / s
    if mirror:
        u = 1.0 - u
    u = u[(u >= -GROW) & (u <= 1.0 + GROW)]
    f = np.zeros(N_FEATURES)
    f[-3] = np.log(s)
    if len(u) < 3:
        f[:len(QUANTILES)] = 0.5
        f[-1] = 1.0
        return f
    # sorted once: the quantiles of sorted values (the same order statistics, found at once), the profile and
    # the share inside from binary searches (the bins of np.histogram: [e_i, e_i+1), the last one closed)
    u = np.sort(u)
    f[:len(QUANTILES)] = sorted_quantiles(u, _Q)
    below = np.searchsorted(u, PROFILE_EDGES, side="left")
    hist = np.diff(below)
    hist[-1] += np.searchsorted(u, PROFILE_EDGES[-1], side="right") - below[-1]
    f[len(QUANTILES):len(QUANTILES) + BINS] = hist / len(u)
    f[-2] = (np.searchsorted(u, 1.0, side="right") - np.searchsorted(u, 0.0, side="left")) / len(u)
    return f


def box_features(points_in, lo: np.ndarray, hi: np.ndarray, extent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Features ``(n, 3, N_FEATURES)`` by role of boxes ``(n, 3)`` (canonical metres), and their roles.

    ``points_in(lo, hi)`` returns the canonical points of a metric box (at least).
    """
    n = len(lo)
    roles = axis_roles(lo, hi)
    mirror = _mirrored(lo, hi, extent)
    out = np.zeros((n, 3, N_FEATURES))
    for i in range(n):
        size = hi[i] - lo[i]
        pts = points_in(np.maximum(lo[i] - GROW * size, 0.0), np.minimum(hi[i] + GROW * size, extent))
        within = (pts >= lo[i]) & (pts <= hi[i])  # once for the three axes
        for r in range(3):
            a = roles[i, r]
            out[i, r] = axis_features(pts, lo[i], hi[i], a, bool(mirror[i, a]), within)
    return out, roles


def face_targets(lo: np.ndarray, hi: np.ndarray, gt_lo: np.ndarray, gt_hi: np.ndarray,
                 extent: np.ndarray) -> np.ndarray:
    """Offsets ``(n, 3, 2)`` by role of the ground-truth faces from the box's, in box sizes (mirrored as features)."""
    roles = axis_roles(lo, hi)
    mirror = _mirrored(lo, hi, extent)
    t = np.zeros((len(lo), 3, 2))
    for r in range(3):
        a = roles[:, r]
        rows = np.arange(len(lo))
        l, h, gl, gh = lo[rows, a], hi[rows, a], gt_lo[rows, a], gt_hi[rows, a]
        s = np.maximum(h - l, 1e-6)
        m = mirror[rows, a]
        # mirrored: the first face is the high one, read backwards
        t[:, r, 0] = np.where(m, (h - gh) / s, (gl - l) / s)
        t[:, r, 1] = np.where(m, (l - gl) / s, (gh - h) / s)
    return t


def moved_boxes(lo: np.ndarray, hi: np.ndarray, offsets: np.ndarray, extent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Boxes with their faces moved by ``offsets`` ``(n, 3, 2)`` (as :func:`face_targets`), kept in the space.

    An offset is at most ``GROW`` box sizes (the features see no further); a box that would
    shrink below a fifth of its size along an axis keeps that axis.
    """
    roles = axis_roles(lo, hi)
    mirror = _mirrored(lo, hi, extent)
    ext = np.broadcast_to(extent, lo.shape)
    nlo, nhi = lo.copy(), hi.copy()
    rows = np.arange(len(lo))
    d = np.clip(offsets, -GROW, GROW)
    for r in range(3):
        a = roles[:, r]
        l, h = lo[rows, a], hi[rows, a]
        s = h - l
        m = mirror[rows, a]
        new_l = np.where(m, l - d[:, r, 1] * s, l + d[:, r, 0] * s)
        new_h = np.where(m, h - d[:, r, 0] * s, h + d[:, r, 1] * s)
        new_l, new_h = np.maximum(new_l, 0.0), np.minimum(new_h, ext[rows, a])
        ok = new_h - new_l >= 0.2 * s
        nlo[rows, a] = np.where(ok, new_l, l)
        nhi[rows, a] = np.where(ok, new_h, h)
    return nlo, nhi


@dataclass
class BoxFit:
    """Per class, role and face, a linear predictor of the ground-truth face's offset (box sizes).

    ``coef[c, r, f]`` has ``N_FEATURES`` weights on the raw features then the intercept;
    ``enabled[c]``: the class uses it (validated on the training buildings).
    """

    coef: np.ndarray  # (12, 3, 2, N_FEATURES + 1)
    enabled: np.ndarray  # (12,) bool
    report: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.coef = np.asarray(self.coef, dtype=np.float64)
        self.enabled = np.asarray(self.enabled, dtype=bool)
        if self.coef.shape != (N_CLASSES, 3, 2, N_FEATURES + 1) or self.enabled.shape != (N_CLASSES,):
            raise ValueError(f"box regression arrays of shapes {self.coef.shape} and {self.enabled.shape}, expected "
                             f"{(N_CLASSES, 3, 2, N_FEATURES + 1)} and {(N_CLASSES,)}")

    def predict(self, class_code: np.ndarray, feats: np.ndarray) -> np.ndarray:
        """Face offsets ``(n, 3, 2)`` of boxes of classes ``class_code`` from their features ``(n, 3, F)``."""
        w = self.coef[np.asarray(class_code, dtype=np.int64)]  # (n, 3, 2, F + 1)
        return np.einsum("nrf,nrkf->nrk", feats, w[..., :-1]) + w[..., -1]

    def apply(self, lo_m: np.ndarray, hi_m: np.ndarray, class_code: np.ndarray, points_in,
              extent: np.ndarray) -> None:
        """Move in place the boxes (canonical metres) of the enabled classes."""
        sel = np.nonzero(self.enabled[np.asarray(class_code, dtype=np.int64)])[0]
        if not len(sel):
            return
        feats, _ = box_features(points_in, lo_m[sel], hi_m[sel], extent)
        nlo, nhi = moved_boxes(lo_m[sel], hi_m[sel], self.predict(class_code[sel], feats), extent)
        lo_m[sel], hi_m[sel] = nlo, nhi

    def to_arrays(self) -> dict[str, np.ndarray]:
        return {"boxfit_coef": self.coef, "boxfit_enabled": self.enabled}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], report: dict[str, Any] | None = None) -> BoxFit | None:
        if "boxfit_coef" not in arrays:
            return None
        return cls(arrays["boxfit_coef"], arrays["boxfit_enabled"], dict(report or {}))


def _ridge(x: np.ndarray, y: np.ndarray, alpha: float) -> np.ndarray:
    """Ridge weights ``(F + 1, k)`` on raw features (standardised inside, intercept unpenalised and last)."""
    mu, sd = x.mean(0), x.std(0)
    sd = np.where(sd > 1e-9, sd, 1.0)
    z = (x - mu) / sd
    ym = y.mean(0)
    w = np.linalg.solve(z.T @ z + alpha * np.eye(x.shape[1]), z.T @ (y - ym))
    w_raw = w / sd[:, None]
    return np.vstack([w_raw, ym - mu @ w_raw])


def _role_predictor(f: np.ndarray, t: np.ndarray, alpha: float) -> np.ndarray:
    """Coefficients ``(2, F + 1)`` of one role (both faces) from features ``(n, F)`` and targets ``(n, 2)``."""
    return _ridge(f, t, alpha).T


def _moved_iou(lo, hi, gt_lo, gt_hi, extent, role: int, pred: np.ndarray) -> np.ndarray:
    """IoU with the truth after moving only the faces of one role by ``pred`` ``(n, 2)``."""
    off = np.zeros((len(lo), 3, 2))
    off[:, role] = pred
    return box_iou_rows(*moved_boxes(lo, hi, off, extent), gt_lo, gt_hi)


def fit_boxfit(samples: dict[str, np.ndarray], classes: list[int] | None = None) -> BoxFit:
    """Fit and validate the per-class, per-role regressions on matched training detections.

    ``samples`` (concatenated over spaces): ``cls`` (n,), ``feats`` (n, 3, F), ``targets`` (n, 3, 2),
    ``lo``, ``hi``, ``gt_lo``, ``gt_hi``, ``extent`` (n, 3) canonical metres, ``building`` (n,) ids.
    For each class and axis role, leave-one-building-out predictions for every ridge penalty
    in ``ALPHAS`` are counted: ``wins`` detections that they bring to IoU >= 0.5, ``losses``
    that they take below it.  The role keeps the penalty with the most ``wins - losses``, and
    is used only if ``wins - losses >= 2 sqrt(wins + losses)`` (two standard deviations of a
    fair coin: a chance gain on a few buildings does not move every future detection); a
    role not used has zero coefficients (its faces stay).
    """
    coef = np.zeros((N_CLASSES, 3, 2, N_FEATURES + 1))
    enabled = np.zeros(N_CLASSES, dtype=bool)
    report: dict[str, Any] = {"alphas": list(ALPHAS), "roles": ["thinner horizontal", "wider horizontal", "vertical"],
                              "rule": "wins - losses >= 2 sqrt(wins + losses), leave-one-building-out",
                              "classes": {}}
    cls = samples["cls"]
    for c in (range(N_CLASSES) if classes is None else classes):
        sel = np.nonzero(cls == c)[0]
        blds = samples["building"][sel]
        name = ELEMENT_CLASSES[c]
        if len(sel) < MIN_SAMPLES or len(np.unique(blds)) < MIN_BUILDINGS:
            report["classes"][name] = {"samples": int(len(sel)), "enabled": False,
                                       "why": "too few matched detections or buildings"}
            continue
        f, t = samples["feats"][sel], samples["targets"][sel]
        lo, hi, glo, ghi, ext = (samples[k][sel] for k in ("lo", "hi", "gt_lo", "gt_hi", "extent"))
        good = box_iou_rows(lo, hi, glo, ghi) >= 0.5
        roles = []
        for r in range(3):
            best = None
            for alpha in ALPHAS:
                pred = np.zeros((len(sel), 2))
                for b in np.unique(blds):
                    te = blds == b
                    w = _role_predictor(f[~te, r], t[~te, r], alpha)
                    pred[te] = f[te, r] @ w[:, :-1].T + w[:, -1]
                now = _moved_iou(lo, hi, glo, ghi, ext, r, pred) >= 0.5
                wins, losses = int((now & ~good).sum()), int((good & ~now).sum())
                if best is None or wins - losses > best[0] - best[1]:
                    best = (wins, losses, alpha)
            wins, losses, alpha = best
            on = wins - losses > 0 and wins - losses >= 2.0 * np.sqrt(wins + losses)
            if on:
                coef[c, r] = _role_predictor(f[:, r], t[:, r], alpha)
            roles.append({"alpha": alpha, "wins_cv": wins, "losses_cv": losses, "used": bool(on)})
        enabled[c] = any(r["used"] for r in roles)
        report["classes"][name] = {"samples": int(len(sel)), "buildings": int(len(np.unique(blds))),
                                   "iou50_before": int(good.sum()), "roles": roles, "enabled": bool(enabled[c])}
    return BoxFit(coef, enabled, report)


def box_iou_rows(lo: np.ndarray, hi: np.ndarray, gt_lo: np.ndarray, gt_hi: np.ndarray) -> np.ndarray:
    """IoU of each box with its own ground-truth box (row by row)."""
    ov = np.clip(np.minimum(hi, gt_hi) - np.maximum(lo, gt_lo), 0, None).prod(1)
    union = (hi - lo).prod(1) + (gt_hi - gt_lo).prod(1) - ov
    return np.divide(ov, union, out=np.zeros_like(ov), where=union > 0)
