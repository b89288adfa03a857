"""The linear SVMs of the element detectors (paper section 4): one class's fit, and refits on the same samples.

:func:`fit_svm` is one ``LinearSVC`` (liblinear) on a feature layout's active columns, optionally with
each window's own weights learnt jointly with the class's shared ones; :func:`fit_class` fits one
class on its :class:`engine.training.samples.Samples`; :func:`refit_without` refits a trained model's
SVMs without some feature groups (the ablations of paper Table 3, the per-class feature groups).
Design notes: ``docs/design/training.md``.
"""
from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass, field

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.svm import LinearSVC

from engine.detection.model import Model
from engine.training.samples import Samples
from engine.training.settings import N_CLASSES, TrainSettings


@dataclass
class SVMFit:
    """One class's fitted SVM: shared weights and intercept, and per window (atom) its own part."""

    weights: np.ndarray  # (D,) full layout
    bias: float
    atom_weights: dict[int, np.ndarray] = field(default_factory=dict)  # atom index -> (D,)
    atom_bias: dict[int, float] = field(default_factory=dict)


def fit_svm(pos: np.ndarray, neg: np.ndarray, mask: np.ndarray, c: float, seed: int,
            atoms: tuple[np.ndarray, np.ndarray] | None = None, atom_scale: float = 1.0) -> SVMFit:
    """One linear SVM on the layout's active columns; returns full-layout weights and bias.

    With ``atoms`` (the window of each positive and negative, -1 for none) the SVM is one
    liblinear problem over ``[x, atom_scale * x (x) e_a, atom_scale * e_a]``: weights shared by
    the class plus each window's own weights and intercept, learnt jointly (the shared part is
    what windows have in common, the window's own part what only its shape shows: an open
    door's leaf, a low bookcase's top).  A window's score is then the sum of both parts, all
    in one margin, so scores of different windows stay comparable.  ``atom_scale`` weighs the
    windows' own parts against the shared one in the regulariser (larger: freer windows).
    """
    x = np.concatenate([pos, neg])[:, mask].astype(np.float64)
    y = np.concatenate([np.ones(len(pos)), -np.ones(len(neg))])
    svm = LinearSVC(C=c, class_weight="balanced", loss="squared_hinge", dual="auto", max_iter=5000,
                    random_state=seed)
    ids = np.zeros(0, dtype=np.int64)
    if atoms is not None:
        at = np.concatenate(atoms).astype(np.int64)
        ids = np.unique(at[at >= 0])
    if len(ids):
        x_fit = _atom_design(x, at, ids, atom_scale)
    else:
        x_fit = x
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        svm.fit(x_fit, y)
    d = int(mask.sum())
    coef = svm.coef_[0]
    w = np.zeros(len(mask))
    w[mask] = coef[:d]
    out = SVMFit(w, float(svm.intercept_[0]))
    for j, a in enumerate(ids.tolist()):
        block = coef[d + j * (d + 1): d + (j + 1) * (d + 1)] * atom_scale
        wa = np.zeros(len(mask))
        wa[mask] = block[:d]
        out.atom_weights[a], out.atom_bias[a] = wa, float(block[d])
    return out


def _atom_design(x: np.ndarray, atom: np.ndarray, ids: np.ndarray, scale: float):
    """Sparse ``[x, scale * x (x) e_a, scale * e_a]``: each row's features again in its window's block."""
    import scipy.sparse as sp

    n, d = x.shape
    block = np.searchsorted(ids, atom)
    has = (atom >= 0)
    rows = np.nonzero(has)[0]
    cols = (block[rows] * (d + 1))[:, None] + np.arange(d + 1)[None]
    vals = np.concatenate([x[rows], np.ones((len(rows), 1))], axis=1) * scale
    own = sp.csr_matrix((vals.ravel(), cols.ravel(), np.concatenate([[0], np.cumsum(has * (d + 1))])),
                        shape=(n, len(ids) * (d + 1)))
    return sp.hstack([sp.csr_matrix(x), own], format="csr")


def fit_class(s: Samples, mask: np.ndarray, settings: TrainSettings) -> SVMFit:
    """The SVM of one class on its samples (with each window's own part when ``settings.atom_weights``)."""
    atoms = (np.concatenate(s.pos_atom), np.concatenate(s.neg_atom)) if settings.atom_weights else None
    return fit_svm(np.concatenate(s.pos), np.concatenate(s.neg), mask, settings.c, settings.seed, atoms,
                   settings.atom_scale)


def refit_without(model: Model, samples: dict[int, Samples], disabled: tuple[str, ...],
                  settings: TrainSettings | None = None) -> Model:
    """The model's SVMs fitted again on the same samples without the feature groups ``disabled``.

    A cheap ablation (paper Table 3): the dictionary and the training vectors are the
    model's own, so the negatives were mined with the full model's detectors, not with
    the ablated ones (a full ablation would mine again with every pass over the spaces).

    Parameters
    ----------
    model, samples
        A model and its samples, as :func:`engine.training.train.train_with_samples` returns them.
    disabled
        Feature groups to leave out (:data:`engine.detection.layout.ABLATIONS` values), added to the
        model's own disabled groups.
    settings
        The SVM's ``c`` and ``seed`` (default: the model's training settings).
    """
    kw = model.svm.get("settings", {})
    if settings is None:
        settings = TrainSettings(c=float(kw.get("c", 0.05)), seed=int(kw.get("seed", 0)),
                                 atom_weights=bool(kw.get("atom_weights", False)),
                                 atom_scale=float(kw.get("atom_scale", 1.0)))
    layout = model.layout.without(disabled)
    weights, bias = np.zeros_like(model.weights), np.zeros_like(model.bias)
    n_atoms = len(model.dictionary.atoms_)
    atom_w, atom_b = np.zeros((n_atoms, layout.size)), np.zeros(n_atoms)
    trained = model.trained.copy()
    for cl in range(N_CLASSES):
        s = samples.get(cl)
        if not trained[cl] or s is None or not s.pos or not s.neg:
            trained[cl] = False
            continue
        fit = fit_class(s, layout.mask, settings)
        weights[cl], bias[cl] = fit.weights, fit.bias
        for a, wa in fit.atom_weights.items():
            atom_w[a], atom_b[a] = wa, fit.atom_bias[a]
    own = {"atom_weights": atom_w, "atom_bias": atom_b} if settings.atom_weights else \
        {"atom_weights": None, "atom_bias": None}
    # the CRF and the re-ranking were learnt on the full model's scores: not this model's
    out = dataclasses.replace(model, layout=layout, weights=weights, bias=bias, trained=trained,
                              crf=None, crf_arrays={}, rescorer=None, **own)
    out.svm = dict(model.svm, ablation={"disabled": list(disabled),
                                        "samples": "the full model's (negatives mined with all features)"})
    return out
