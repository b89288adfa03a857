"""The detection model file: documented arrays in ``<stem>.npz`` plus ``<stem>.json``, never pickle.

The npz holds the linear SVMs (``weights``, ``bias``, ``trained``), the window dictionary (``atom_*``), and
optionally each window's own part of its class's SVM (version 2), the learned box regression (``boxfit_*``,
version 3), the learned re-ranking (``rescore_*``, version 4) and the CRF's arrays (``crf_*``); the JSON the
layout, grid, settings, dictionary parameters, provenance and the arrays' descriptions.  The CRF engineer's
slot: :attr:`Model.crf` (JSON) and :attr:`Model.crf_arrays` are written and read back unchanged.
The arrays, their shapes and the JSON keys: ``docs/design/detection.md`` (the model file).
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from engine.detection.boxfit import BoxFit
from engine.detection.dictionary import WindowDictionary
from engine.detection.layout import FeatureLayout
from engine.detection.rescore import Rescorer
from tiles.classes import ELEMENT_CLASSES
from tiles.errors import UserError

FORMAT = "buildingparser-detector"
#: The newest version this code reads; a model is written as version 1, 2 with per-window weights, 3 with a
#: learned box regression, 4 with a learned re-ranking.
VERSION = 4
ARRAY_DOCS = {
    "weights": "float64 (12, D): linear SVM weights per element class, zero on disabled feature groups",
    "bias": "float64 (12,): SVM intercept per class",
    "trained": "bool (12,): the class had training examples",
    "atom_class": "int16 (A,): class code of each dictionary window",
    "atom_unit_size": "float64 (A, 3): mean size in the unit cube",
    "atom_metric_size": "float64 (A, 3): mean size in metres",
    "atom_relative": "bool (A, 3): per axis, the size follows the space (unit cube) instead of metres",
    "atom_occupancy": "bool (A, K, K, K): occupancy pattern (cell-wise mode of the cluster)",
    "atom_members": "int64 (A,): training instances in the window's cluster",
    "atom_weights": "float64 (A, D): each window's own part of its class's SVM weights (added to weights[class])",
    "atom_bias": "float64 (A,): each window's own part of its class's SVM intercept (added to bias[class])",
    "boxfit_coef": "float64 (12, 3, 2, F + 1): box regression weights per class, axis role (thinner horizontal, "
                   "wider horizontal, vertical) and face (towards the space's nearer end first), intercept last",
    "boxfit_enabled": "bool (12,): the class's detections are moved by the box regression",
    "rescore_mean": "float64 (12, F): re-ranking feature means per class (engine.detection.rescore.rescore_features)",
    "rescore_scale": "float64 (12, F): re-ranking feature standard deviations per class",
    "rescore_coef": "float64 (12, F): logistic re-ranking weights per class on the standardised features",
    "rescore_bias": "float64 (12,): logistic re-ranking intercept per class",
    "rescore_enabled": "bool (12,): the class's detections take the re-ranked score (log-odds)",
}


def model_stem(path: str | os.PathLike) -> str:
    """``path`` without a ``.npz`` / ``.json`` suffix."""
    p = os.fspath(path)
    for ext in (".npz", ".json"):
        if p.endswith(ext):
            return p[: -len(ext)]
    return p


@dataclass
class Model:
    """A trained element detector: feature layout, window dictionary, one linear SVM per class.

    A window (dictionary atom) ``a`` of class ``c`` scores with ``weights[c] + atom_weights[a]`` and
    ``bias[c] + atom_bias[a]`` (:meth:`window_weights`): the class's shared SVM plus the window's own
    part, learnt jointly (``detection.train.atom-weights``); models without them have zeros there.
    """

    layout: FeatureLayout
    dictionary: WindowDictionary
    weights: np.ndarray  # (12, D)
    bias: np.ndarray  # (12,)
    trained: np.ndarray  # (12,) bool
    voxel: float = 0.1
    max_cells: int = 2_000_000
    stride: float = 0.25
    detection: dict[str, Any] = field(default_factory=dict)
    svm: dict[str, Any] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)
    cv: dict[str, Any] | None = None
    crf: dict[str, Any] | None = None
    crf_arrays: dict[str, np.ndarray] = field(default_factory=dict)
    atom_weights: np.ndarray | None = None  # (A, D)
    atom_bias: np.ndarray | None = None  # (A,)
    boxfit: BoxFit | None = None  # learned box regression (engine.detection.boxfit)
    rescorer: Rescorer | None = None  # learned re-ranking of the final boxes (engine.detection.rescore)

    def __post_init__(self) -> None:
        self.weights = np.asarray(self.weights, dtype=np.float64)
        self.bias = np.asarray(self.bias, dtype=np.float64)
        self.trained = np.asarray(self.trained, dtype=bool)
        n = len(ELEMENT_CLASSES)
        if self.weights.shape != (n, self.layout.size):
            raise ValueError(f"weights of shape {self.weights.shape}, expected {(n, self.layout.size)}")
        if self.bias.shape != (n,) or self.trained.shape != (n,):
            raise ValueError("bias and trained need one value per element class")
        if self.dictionary.k != self.layout.k:
            raise ValueError("dictionary and feature layout disagree on K")
        n_atoms = len(self.dictionary.atoms_)
        if (self.atom_weights is None) != (self.atom_bias is None):
            raise ValueError("atom_weights and atom_bias go together")
        if self.atom_weights is not None:
            self.atom_weights = np.asarray(self.atom_weights, dtype=np.float64)
            self.atom_bias = np.asarray(self.atom_bias, dtype=np.float64)
            if self.atom_weights.shape != (n_atoms, self.layout.size) or self.atom_bias.shape != (n_atoms,):
                raise ValueError(f"atom weights of shape {self.atom_weights.shape} and bias {self.atom_bias.shape}, "
                                 f"expected {(n_atoms, self.layout.size)} and {(n_atoms,)}")
        bad = [k for k in self.crf_arrays if not k.startswith("crf_")]
        if bad:
            raise ValueError(f"CRF arrays must be named crf_*: {bad}")

    def window_weights(self, atoms) -> tuple[np.ndarray, np.ndarray]:
        """SVM weights ``(n, D)`` and intercepts ``(n,)`` that windows of dictionary atoms ``atoms`` score with."""
        atoms = np.asarray(atoms, dtype=np.int64).reshape(-1)
        codes = np.array([self.dictionary.atoms_[a].class_code for a in atoms], dtype=np.int64)
        w, b = self.weights[codes], self.bias[codes]
        if self.atom_weights is not None:
            w, b = w + self.atom_weights[atoms], b + self.atom_bias[atoms]
        return w, b

    def arrays(self) -> dict[str, np.ndarray]:
        out = {"weights": self.weights, "bias": self.bias, "trained": self.trained}
        if self.atom_weights is not None:
            out.update(atom_weights=self.atom_weights, atom_bias=self.atom_bias)
        if self.boxfit is not None:
            out.update(self.boxfit.to_arrays())
        if self.rescorer is not None:
            out.update(self.rescorer.to_arrays())
        out.update(self.dictionary.to_arrays())
        out.update(self.crf_arrays)
        return out

    def params(self) -> dict[str, Any]:
        docs = dict(ARRAY_DOCS)
        docs.update({k: "CRF array (engine.crf.model)" for k in self.crf_arrays})
        if self.atom_weights is None:
            docs = {k: v for k, v in docs.items() if not k.startswith("atom_weights") and k != "atom_bias"}
        if self.boxfit is None:
            docs = {k: v for k, v in docs.items() if not k.startswith("boxfit_")}
        if self.rescorer is None:
            docs = {k: v for k, v in docs.items() if not k.startswith("rescore_")}
        version = 4 if self.rescorer is not None else 3 if self.boxfit is not None else \
            1 if self.atom_weights is None else 2
        return {"format": FORMAT, "version": version, "classes": list(ELEMENT_CLASSES),
                "layout": self.layout.to_json(), "voxel": self.voxel, "max_cells": self.max_cells,
                "stride": self.stride, "detection": self.detection, "dictionary": self.dictionary.params(),
                "svm": self.svm, "provenance": self.provenance, "cv": self.cv, "crf": self.crf,
                "boxfit": None if self.boxfit is None else self.boxfit.report,
                "rescore": None if self.rescorer is None else self.rescorer.report, "arrays": docs}

    def save(self, path: str | os.PathLike) -> tuple[str, str]:
        """Write ``<stem>.npz`` and ``<stem>.json``; returns their paths."""
        stem = model_stem(path)
        d = os.path.dirname(stem)
        if d:
            os.makedirs(d, exist_ok=True)
        np.savez_compressed(stem + ".npz", **self.arrays())
        with open(stem + ".json", "w") as f:
            json.dump(self.params(), f, indent=1, default=_json_default)
            f.write("\n")
        return stem + ".npz", stem + ".json"

    @classmethod
    def load(cls, path: str | os.PathLike) -> Model:
        """Read a model written by :meth:`save` (no pickle); a :class:`UserError` if it is not one."""
        stem = model_stem(path)
        for ext in (".json", ".npz"):
            if not os.path.isfile(stem + ext):
                raise UserError(stem + ext, "no such model file (a model is <stem>.npz + <stem>.json)")
        try:
            with open(stem + ".json") as f:
                params = json.load(f)
        except (OSError, json.JSONDecodeError) as exc:
            raise UserError(stem + ".json", f"not a model description ({exc})") from None
        if not isinstance(params, dict) or params.get("format") != FORMAT:
            raise UserError(stem + ".json", f"not a buildingparser detection model (format {FORMAT!r} expected)")
        _check_params(params, stem + ".json")
        if int(params.get("version", 0)) > VERSION:
            raise UserError(stem + ".json", f"model version {params.get('version')} is newer than this "
                                            f"buildingparser reads ({VERSION}): upgrade buildingparser")
        if list(params.get("classes", [])) != list(ELEMENT_CLASSES):
            raise UserError(stem + ".json", "model trained for other classes")
        try:
            with np.load(stem + ".npz", allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
        except (OSError, ValueError) as exc:
            raise UserError(stem + ".npz", f"not a model array file ({exc})") from None
        for name in ("weights", "bias", "atom_weights", "atom_bias"):
            a = arrays.get(name)
            if a is not None and (a.dtype.kind not in "biuf" or not np.isfinite(a).all()):
                raise UserError(stem + ".npz", f"array {name} must hold finite numbers (it is {a.dtype}"
                                               + (f" with {int(np.size(a) - np.isfinite(a).sum())} non-finite)"
                                                  if a.dtype.kind == "f" else ")"))
        try:
            layout = FeatureLayout.from_json(params["layout"])
            dictionary = WindowDictionary.from_arrays(arrays, params["dictionary"])
            model = cls(layout, dictionary, arrays["weights"], arrays["bias"], arrays["trained"],
                       voxel=float(params["voxel"]), max_cells=int(params["max_cells"]),
                       stride=float(params["stride"]), detection=params.get("detection", {}),
                       svm=params.get("svm", {}), provenance=params.get("provenance", {}), cv=params.get("cv"),
                       crf=params.get("crf"),
                       crf_arrays={k: v for k, v in arrays.items() if k.startswith("crf_")},
                       atom_weights=arrays.get("atom_weights"), atom_bias=arrays.get("atom_bias"),
                       boxfit=BoxFit.from_arrays(arrays, params.get("boxfit")),
                       rescorer=Rescorer.from_arrays(arrays, params.get("rescore")))
        except (KeyError, ValueError, TypeError, IndexError, AttributeError) as exc:
            raise UserError(stem + ".npz", f"incomplete or inconsistent model ({type(exc).__name__}: {exc})") \
                from None
        from engine.crf.model import FORMAT as CRF_FORMAT
        from engine.crf.model import CRFWeights

        if isinstance(model.crf, dict) and model.crf.get("format") == CRF_FORMAT:  # (the slot holds any JSON)
            try:
                CRFWeights.from_model(model)  # checked now, not when the CRF stage comes after the detection
            except (KeyError, ValueError, TypeError, IndexError, AttributeError) as exc:
                raise UserError(stem + ".npz", f"its CRF weights are not valid ({exc})") from None
        return model


#: JSON fields a model must have, with their type and what their value must be.
_PARAM_RULES: dict[str, tuple[type | tuple[type, ...], Any, str]] = {
    "version": (int, lambda v: v >= 1, "an integer >= 1"),
    "voxel": ((int, float), lambda v: math.isfinite(v) and v > 0, "a finite number of metres > 0"),
    "max_cells": (int, lambda v: v >= 1, "an integer >= 1"),
    "stride": ((int, float), lambda v: math.isfinite(v) and 0 < v <= 1, "a fraction in (0, 1]"),
    "layout": (dict, lambda v: True, "an object"),
    "dictionary": (dict, lambda v: True, "an object"),
    "classes": (list, lambda v: True, "a list of class names"),
}


def _check_params(params: dict[str, Any], path: str) -> None:
    """Each JSON field of :data:`_PARAM_RULES` present, of its type and in its range; a one-line UserError."""
    for key, (types, ok, what) in _PARAM_RULES.items():
        if key not in params:
            raise UserError(path, f"model description lacks {key!r}")
        v = params[key]
        if isinstance(v, bool) or not isinstance(v, types) or not ok(v):
            raise UserError(path, f"model field {key} = {json.dumps(v)[:60]}: must be {what}")
    for key in ("detection", "svm", "provenance", "cv", "crf", "boxfit", "rescore"):
        if params.get(key) is not None and not isinstance(params[key], dict):
            raise UserError(path, f"model field {key} must be an object or null, not {type(params[key]).__name__}")


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def default_model_path() -> str:
    """The model shipped with the package (``engine/models/default``)."""
    return os.path.join(os.path.dirname(os.path.dirname(__file__)), "models", "default")


def load_model(path: str | os.PathLike | None = None) -> Model:
    """A model from ``path``, or the shipped default model."""
    return Model.load(path if path is not None else default_model_path())
