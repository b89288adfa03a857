"""The CRF's parameters (paper 4.1): :class:`CRFWeights` and :class:`CRFSettings`.

The weights are ``w0`` on the detector's score, a bias per class and one weight vector per unordered
class pair (the layout of :func:`pair_index`); they live in arrays + JSON, never pickle.  The
settings bound each space's graph and its CP-SAT solve (``buildingparser.crf.*``,
``engine/crf/crf.yaml``).  Design notes: ``docs/design/crf.md``.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from engine import config
from tiles.classes import ELEMENT_CLASSES, element_class_list

#: Classes that take part in the CRF (the 12 element classes; clutter is not an element).
N_CLASSES = len(ELEMENT_CLASSES)
#: Unordered class pairs ``(a, b)``, ``a <= b``, in the order of :attr:`CRFWeights.edge`'s rows.
CLASS_PAIRS: tuple[tuple[int, int], ...] = tuple((a, b) for a in range(N_CLASSES) for b in range(a, N_CLASSES))
#: ``PAIR_INDEX[a, b]``: the row of :attr:`CRFWeights.edge` for classes ``a`` and ``b`` (either order).
PAIR_INDEX = np.zeros((N_CLASSES, N_CLASSES), dtype=np.int64)
for _i, (_a, _b) in enumerate(CLASS_PAIRS):
    PAIR_INDEX[_a, _b] = PAIR_INDEX[_b, _a] = _i

FORMAT = "buildingparser-crf"
#: 2: the per-class ``decides`` mask (``crf_decides``); version-1 weights load with every class decided.
FORMAT_VERSION = 2
#: Names of the blocks of one edge feature vector, in order (see ``docs/design/crf.md``).
EDGE_FEATURE_BLOCKS = ("B_u", "B_v", "S_u", "S_v", "abs_dP", "const", "iou")


def pair_index(a: int, b: int) -> int:
    """Row of :attr:`CRFWeights.edge` that weighs edges between classes ``a`` and ``b`` (either order)."""
    return int(PAIR_INDEX[a, b])


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
        are fixed in the integer program (:func:`engine.crf.solve.fix_labels`).  ``train-crf`` keeps only the classes
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
    def new(cls, grid: int, *, k: int | dict[str, int] | None = None, w0: float = 1.0) -> CRFWeights:
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
        """All weights as one vector ``[w0, bias, edge.ravel()]`` (the layout of
        :func:`engine.crf.graph.joint_feature`)."""
        return np.concatenate([[self.w0], self.bias, self.edge.ravel()])

    def with_vector(self, vec: np.ndarray) -> CRFWeights:
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
    def from_arrays(cls, arrays: dict[str, np.ndarray], params: dict[str, Any], prefix: str = "crf_") -> CRFWeights:
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
    def load(cls, path: str | os.PathLike) -> CRFWeights:
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
    def from_model(cls, model: Any) -> CRFWeights | None:
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
    base = config.setting("crf.k")
    per = config.setting("crf.k-per-class") if overrides is None else dict(overrides)
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
    """How the CRF of one space is bounded and solved (read on the driver, sent to the tasks).

    ``keep_classes``: the proposals of these classes are always kept, whatever their score or the CRF
    (a space's one ceiling and one floor: the detector gives each space exactly one of each).
    """

    max_nodes_per_class: int = 40
    seed: int = 0
    linearization_level: int = 2
    deterministic_time: float = 20.0
    time_limit: float = 30.0
    resolution: int = 1_000_000
    keep_classes: tuple[str, ...] = ("ceiling", "floor")

    def __post_init__(self) -> None:
        object.__setattr__(self, "keep_classes", element_class_list(self.keep_classes, "keep-classes"))
        if self.max_nodes_per_class < 1:
            raise ValueError(f"max-nodes-per-class must be >= 1, not {self.max_nodes_per_class}")
        if self.linearization_level not in (0, 1, 2):
            raise ValueError(f"linearization-level must be 0, 1 or 2, not {self.linearization_level}")
        if not (self.deterministic_time > 0 and self.time_limit > 0):
            raise ValueError("deterministic-time and time-limit must be positive")
        if not 1 <= self.resolution <= 2 ** 40:
            raise ValueError(f"objective-resolution must be in [1, 2^40], not {self.resolution}")

    @classmethod
    def from_config(cls, **overrides: Any) -> CRFSettings:
        """``buildingparser.crf.*`` settings, with keyword overrides (None = use the setting)."""
        vals = config.settings_fields(cls, "crf", keys={
            "max_nodes_per_class": "max-nodes-per-class", "seed": "seed",
            "linearization_level": "linearization-level", "deterministic_time": "deterministic-time",
            "time_limit": "time-limit", "resolution": "objective-resolution", "keep_classes": "keep-classes"})
        vals.update({k: v for k, v in overrides.items() if v is not None})
        return cls(**vals)

