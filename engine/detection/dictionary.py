"""The learned dictionary of candidate windows (paper section 4, "Learning candidate windows").

For each class, the training instances' tightest boxes (in their space's
canonical frame) and occupancy patterns (K x K x K) are grouped with Affinity
Propagation (scikit-learn, ``affinity="precomputed"``).  The similarity of two
instances is ``IoU^w * agreement^(1 - w) - 1`` (``w = iou_weight``, a weighted
geometric mean, so that a poor IoU is not made up for by agreeing patterns) where
``agreement`` is the fraction of the K^3 sub-boxes on which their occupancy
patterns agree and IoU is the overlap of their two boxes placed at a common
corner.  One addition to the paper: IoU is taken per axis in the frame where the
two sizes agree more, the unit cube or metres (a wall's length is a fraction of
the room, its thickness is metres; a chair's size is metres whatever the room);
IoU is invariant to rescaling an axis, so this is still the IoU of two boxes.

Each cluster gives one window: size = the mean of its members' sizes, occupancy
= the cell-wise mode (majority) of their patterns.  Along each axis the window
keeps its size *relative* to the space (unit cube) only where its members vary
clearly less in that frame than in metres (coefficient of variation at most
``relative_ratio`` times, default half: a wall window is as long as the room, a
chair window as big as a chair, and a board 1.2-2.4 m wide in rooms of any size,
which varies about as much in both frames, keeps metres instead of growing to
4 m in a long room); a single member is relative where it spans at least half
the space.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from sklearn.cluster import AffinityPropagation
from sklearn.exceptions import ConvergenceWarning

from tiles.classes import ELEMENT_CLASSES


def size_iou(unit: np.ndarray, metric: np.ndarray) -> np.ndarray:
    """Pairwise IoU ``(n, n)`` of boxes at a common corner, each axis compared in its better-agreeing frame."""
    def ratio(s):
        s = np.maximum(s, 1e-9)
        return np.minimum(s[:, None, :], s[None]) / np.maximum(s[:, None, :], s[None])

    use_unit = ratio(unit) >= ratio(metric)  # (n, n, 3)
    # per axis, pick the frame; relative sizes within that frame
    a = np.where(use_unit, np.maximum(unit, 1e-9)[:, None, :], np.maximum(metric, 1e-9)[:, None, :])
    b = np.where(use_unit, np.maximum(unit, 1e-9)[None], np.maximum(metric, 1e-9)[None])
    inter = np.prod(np.minimum(a, b), axis=2)
    return inter / (np.prod(a, axis=2) + np.prod(b, axis=2) - inter)


def occupancy_agreement(occ: np.ndarray) -> np.ndarray:
    """Pairwise fraction ``(n, n)`` of sub-boxes on which two occupancy patterns agree."""
    f = occ.reshape(len(occ), -1).astype(np.float64)
    both = f @ f.T
    neither = (1 - f) @ (1 - f).T
    return (both + neither) / f.shape[1]


@dataclass
class Atom:
    """One candidate window of the dictionary."""

    class_code: int
    unit_size: np.ndarray  # (3,) mean size in the unit cube
    metric_size: np.ndarray  # (3,) mean size in metres
    relative: np.ndarray  # (3,) bool: size follows the space (unit cube) along this axis
    occupancy: np.ndarray  # (K, K, K) bool
    members: int

    def size_in(self, extent: np.ndarray) -> np.ndarray:
        """The window's size in metres in a space of ``extent`` metres (at most the space)."""
        extent = np.asarray(extent, dtype=np.float64)
        return np.minimum(np.where(self.relative, self.unit_size * extent, self.metric_size), extent)


class WindowDictionary:
    """Affinity-Propagation dictionary of window shapes per class (scikit-learn style estimator).

    Parameters
    ----------
    k
        Sub-boxes per axis of the occupancy patterns.
    iou_weight
        Exponent of the box IoU against occupancy agreement in the similarity.
    preference_quantile
        AP preference = this quantile of the similarities (0.5 is scikit-learn's median);
        lower values give fewer windows.
    max_instances
        At most this many instances per class are clustered (a seeded random subset).
    max_atoms
        At most this many windows per class (the clusters with most members).
    min_gap
        The preference is at most ``-min_gap``: instances whose similarity is within
        ``min_gap`` of 0 (near-identical) always share a window.
    damping, max_iter, random_state
        Passed to :class:`sklearn.cluster.AffinityPropagation`.
    relative_ratio
        An axis of a window is relative (follows the space) when its members' coefficient of
        variation in the unit cube is at most this fraction of theirs in metres; where neither varies
        (one member), when it spans at least half the space.  None: the rule of models written
        before this parameter existed (relative when it varies at most as much as in metres).
    """

    def __init__(self, k: int = 4, *, iou_weight: float = 0.5, preference_quantile: float = 0.5,
                 max_instances: int = 400, max_atoms: int = 12, damping: float = 0.7, max_iter: int = 500,
                 min_gap: float = 0.1, random_state: int = 0, relative_ratio: float | None = 0.5):
        self.k = k
        self.iou_weight = iou_weight
        self.preference_quantile = preference_quantile
        self.max_instances = max_instances
        self.max_atoms = max_atoms
        self.damping = damping
        self.max_iter = max_iter
        self.min_gap = min_gap
        self.random_state = random_state
        self.relative_ratio = relative_ratio

    def _validate(self) -> None:
        if int(self.k) < 1:
            raise ValueError("k must be >= 1")
        if not 0.0 <= self.iou_weight <= 1.0:
            raise ValueError("iou_weight must be in [0, 1]")
        if not 0.0 <= self.preference_quantile <= 1.0:
            raise ValueError("preference_quantile must be in [0, 1]")
        if not 0.5 <= self.damping < 1.0:
            raise ValueError("damping must be in [0.5, 1)")
        if not 0.0 <= self.min_gap <= 1.0:
            raise ValueError("min_gap must be in [0, 1]")
        if self.max_instances < 1 or self.max_atoms < 1:
            raise ValueError("max_instances and max_atoms must be >= 1")

    def similarity(self, unit: np.ndarray, metric: np.ndarray, occ: np.ndarray) -> np.ndarray:
        """The AP similarity matrix of instances (``<= 0``, 0 on identical ones)."""
        iou = size_iou(unit, metric)
        agree = occupancy_agreement(occ)
        return iou ** self.iou_weight * agree ** (1.0 - self.iou_weight) - 1.0

    def fit(self, class_codes: np.ndarray, unit_sizes: np.ndarray, metric_sizes: np.ndarray,
            occupancy: np.ndarray) -> WindowDictionary:
        """Cluster the instances of each class into windows.

        Parameters
        ----------
        class_codes
            ``(n,)`` element class of each training instance.
        unit_sizes, metric_sizes
            ``(n, 3)`` tightest-box sizes in the unit cube and in metres (canonical axes).
        occupancy
            ``(n, K, K, K)`` bool occupancy patterns.
        """
        self._validate()
        class_codes = np.asarray(class_codes, dtype=np.int64)
        unit_sizes = np.asarray(unit_sizes, dtype=np.float64).reshape(-1, 3)
        metric_sizes = np.asarray(metric_sizes, dtype=np.float64).reshape(-1, 3)
        occupancy = np.asarray(occupancy, dtype=bool)
        k = int(self.k)
        if occupancy.shape[1:] != (k, k, k):
            raise ValueError(f"occupancy patterns of shape {occupancy.shape[1:]}, expected {(k, k, k)}")
        if not len(class_codes) == len(unit_sizes) == len(metric_sizes) == len(occupancy):
            raise ValueError("one class, size and pattern per instance")
        rng = np.random.default_rng(self.random_state)
        atoms: list[Atom] = []
        for c in range(len(ELEMENT_CLASSES)):
            idx = np.nonzero(class_codes == c)[0]
            if not len(idx):
                continue
            if len(idx) > self.max_instances:
                idx = np.sort(rng.choice(idx, self.max_instances, replace=False))
            labels = self._cluster(unit_sizes[idx], metric_sizes[idx], occupancy[idx])
            found = []
            for lab in np.unique(labels):
                mem = idx[labels == lab]
                found.append(self._atom(c, unit_sizes[mem], metric_sizes[mem], occupancy[mem]))
            found.sort(key=lambda a: (-a.members, *a.metric_size))
            atoms.extend(found[:self.max_atoms])
        self.atoms_ = atoms
        return self

    def _cluster(self, unit: np.ndarray, metric: np.ndarray, occ: np.ndarray) -> np.ndarray:
        n = len(unit)
        if n < 2:
            return np.zeros(n, dtype=np.int64)
        s = self.similarity(unit, metric, occ)
        off = s[~np.eye(n, dtype=bool)]
        if np.allclose(off, 0.0):
            return np.zeros(n, dtype=np.int64)
        if np.ptp(off) == 0.0:  # all pairs equally similar: AP has nothing to choose
            return np.zeros(n, dtype=np.int64) if off[0] > -self.min_gap else np.arange(n, dtype=np.int64)
        # never below the floor: instances closer than ``min_gap`` are not worth two windows
        pref = min(float(np.quantile(off, self.preference_quantile)), -self.min_gap)
        for damping in (self.damping, 0.9):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ConvergenceWarning)
                ap = AffinityPropagation(affinity="precomputed", preference=pref, damping=damping,
                                         max_iter=self.max_iter, convergence_iter=30,
                                         random_state=self.random_state).fit(s)
            if len(ap.cluster_centers_indices_) and np.all(ap.labels_ >= 0):
                return ap.labels_.astype(np.int64)
        return np.zeros(n, dtype=np.int64)  # AP did not converge: one window for the class

    def _atom(self, c: int, unit: np.ndarray, metric: np.ndarray, occ: np.ndarray) -> Atom:
        def cv(s):
            return s.std(axis=0) / np.maximum(s.mean(axis=0), 1e-9)

        cu, cm = cv(unit), cv(metric)
        # relative only where the members clearly follow their spaces (a board 1.2-2.4 m wide in rooms of
        # any size varies as much in both frames: it keeps metres, else it grows with the room); members
        # of one size in both frames (a single instance): relative where they span most of the space
        if self.relative_ratio is None:  # the rule of models written before relative_ratio existed
            relative = cu <= cm
        else:
            relative = np.where((cu < 1e-9) & (cm < 1e-9), unit.mean(axis=0) >= 0.5, cu <= self.relative_ratio * cm)
        occupancy = occ.reshape(len(occ), -1).mean(axis=0).reshape(occ.shape[1:]) >= 0.5
        return Atom(int(c), unit.mean(axis=0), metric.mean(axis=0), relative, occupancy, int(len(unit)))

    # -- arrays for the model file --------------------------------------------------------------
    def to_arrays(self) -> dict[str, np.ndarray]:
        """The dictionary as arrays (see :mod:`engine.detection.model` for their documentation)."""
        a = self.atoms_
        k = int(self.k)
        return {
            "atom_class": np.array([x.class_code for x in a], dtype=np.int16),
            "atom_unit_size": np.array([x.unit_size for x in a], dtype=np.float64).reshape(-1, 3),
            "atom_metric_size": np.array([x.metric_size for x in a], dtype=np.float64).reshape(-1, 3),
            "atom_relative": np.array([x.relative for x in a], dtype=bool).reshape(-1, 3),
            "atom_occupancy": np.array([x.occupancy for x in a], dtype=bool).reshape(-1, k, k, k),
            "atom_members": np.array([x.members for x in a], dtype=np.int64),
        }

    def params(self) -> dict[str, Any]:
        return {"k": int(self.k), "iou_weight": self.iou_weight, "preference_quantile": self.preference_quantile,
                "max_instances": self.max_instances, "max_atoms": self.max_atoms, "damping": self.damping,
                "max_iter": self.max_iter, "min_gap": self.min_gap, "random_state": self.random_state,
                "relative_ratio": self.relative_ratio}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], params: dict[str, Any]) -> WindowDictionary:
        d = cls(**{"relative_ratio": None, **params})  # older models: the rule they were fitted with
        d.atoms_ = [Atom(int(c), us.astype(np.float64), ms.astype(np.float64), rel.astype(bool), occ.astype(bool),
                         int(n))
                    for c, us, ms, rel, occ, n in zip(arrays["atom_class"], arrays["atom_unit_size"],
                                                       arrays["atom_metric_size"], arrays["atom_relative"],
                                                       arrays["atom_occupancy"], arrays["atom_members"])]
        return d

    def atoms_of(self, class_code: int) -> list[Atom]:
        return [a for a in self.atoms_ if a.class_code == class_code]
