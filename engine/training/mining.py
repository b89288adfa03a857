"""Hard-negative mining (paper section 4): rounds of sample collection and SVM refits.

Round 0 collects the first samples (:func:`engine.training.samples.samples_task`) and fits every
class's SVM.  Each later round scans every training space with the current detectors, keeps the
margin violators that are not negatives yet (at most ``hard-negatives`` per class and space) and
refits the classes that got new ones, until no class gets any or ``rounds`` is reached.  Design
notes: ``docs/design/training.md``.
"""
from __future__ import annotations

import dataclasses
import logging
from typing import Any

import numpy as np

from engine.detection.model import Model
from engine.detection.settings import DetectionSettings
from engine.training.jobs import TrainJob
from engine.training.samples import Samples, samples_task
from engine.training.settings import N_CLASSES, TrainSettings
from engine.training.svm import fit_class
from tiles.tasks import run_tasks

logger = logging.getLogger(__name__)


def mine_and_fit(jobs: list[TrainJob], model: Model, trained: np.ndarray, settings: TrainSettings,
                 det: DetectionSettings, client=None
                 ) -> tuple[Model, dict[int, Samples], list[dict[str, Any]], list[TrainJob]]:
    """The SVMs of the ``trained`` classes of ``model`` (its layout and dictionary), with hard-negative mining.

    Parameters
    ----------
    jobs
        The training spaces (their canonical frames computed).
    model
        The untrained model: feature layout, window dictionary.
    trained
        ``(12,)`` the classes to train; a class without positives or negatives is dropped (in place).
    settings, det
        Training and sliding-window settings.
    client
        A ``distributed.Client``; every round runs one task per space.

    Returns
    -------
    model, samples, history, jobs
        The trained model, per class code its training vectors, one record per round, and the jobs
        with the keys of their mined negatives.
    """
    samples = {c: Samples() for c in range(N_CLASSES)}
    history = []
    active = tuple(c for c in range(N_CLASSES) if trained[c])
    for round_ in range(settings.rounds + 1):
        if round_ > 0 and settings.mining == "hardest":
            jobs = _with_mined(jobs, samples)
        res = run_tasks(samples_task, jobs, client=client, label=f"training samples, round {round_}",
                        keys=[f"space {j.key}" for j in jobs], extra_args=(model, settings, round_, det, active))
        new = _add_samples(samples, jobs, res, round_, settings)
        model = _refit(model, samples, trained, new, round_, settings, det)
        history.append({"round": round_, "new_negatives": new.tolist(),
                        "positives": [int(sum(len(x) for x in samples[c].pos)) for c in range(N_CLASSES)],
                        "negatives": [samples[c].n_neg() for c in range(N_CLASSES)]})
        logger.info(f"round {round_}: new negatives {new.tolist()}")
        # classes without new violators are done (their detector no longer changes)
        active = tuple(c for c in active if trained[c] and (round_ == 0 or new[c] > 0))
        if round_ > 0 and not active:
            break
    return model, samples, history, jobs


def _with_mined(jobs: list[TrainJob], samples: dict[int, Samples]) -> list[TrainJob]:
    """The jobs with, per class, the keys of their negatives mined so far."""
    mined: dict[int, dict[int, list[int]]] = {j.key: {} for j in jobs}
    for c in range(N_CLASSES):
        for jk, kk in samples[c].keys:
            mined[jk].setdefault(c, []).append(kk)
    return [dataclasses.replace(j, mined={c: np.array(v, dtype=np.int64) for c, v in mined[j.key].items()})
            for j in jobs]


def _add_samples(samples: dict[int, Samples], jobs: list[TrainJob], res: list[dict[int, dict[str, np.ndarray]]],
                 round_: int, settings: TrainSettings) -> np.ndarray:
    """Add one round's samples of every space to ``samples``; the new negatives per class.

    Positives are all kept; a negative window already kept is not added again, and a class stops
    taking negatives at ``max-negatives``.
    """
    new = np.zeros(N_CLASSES, dtype=np.int64)
    for job, r in zip(jobs, res):
        for c in range(N_CLASSES):
            s = samples[c]
            if len(r[c]["pos"]):
                s.pos.append(r[c]["pos"]), s.pos_atom.append(r[c]["pos_atom"])
            neg, keys, neg_atom = r[c]["neg"], r[c]["keys"], r[c]["neg_atom"]
            if round_ == 0 and len(neg) > len(keys):  # other classes' elements come first, keyless
                s.neg.append(neg[:len(neg) - len(keys)]), s.neg_atom.append(neg_atom[:len(neg) - len(keys)])
                neg, neg_atom = neg[len(neg) - len(keys):], neg_atom[len(neg) - len(keys):]
            fresh = [i for i, kk in enumerate(keys.tolist()) if (job.key, kk) not in s.keys]
            if fresh and s.n_neg() < settings.max_negatives:
                s.keys.update((job.key, keys[i]) for i in fresh)
                s.neg.append(neg[fresh]), s.neg_atom.append(neg_atom[fresh])
                new[c] += len(fresh)
    return new


def _refit(model: Model, samples: dict[int, Samples], trained: np.ndarray, new: np.ndarray, round_: int,
           settings: TrainSettings, det: DetectionSettings) -> Model:
    """The model with the SVMs of the classes that got new samples fitted again (every class in round 0)."""
    layout, dictionary = model.layout, model.dictionary
    weights, bias = model.weights.copy(), model.bias.copy()
    atom_w, atom_b = (model.atom_weights.copy(), model.atom_bias.copy()) if model.atom_weights is not None else \
        (np.zeros((len(dictionary.atoms_), layout.size)), np.zeros(len(dictionary.atoms_)))
    for c in range(N_CLASSES):
        s = samples[c]
        if not trained[c]:
            continue
        if not s.pos or not s.neg:
            trained[c] = False
            continue
        if round_ == 0 or new[c]:
            fit = fit_class(s, layout.mask, settings)
            weights[c], bias[c] = fit.weights, fit.bias
            for a in [i for i, at in enumerate(dictionary.atoms_) if at.class_code == c]:
                atom_w[a], atom_b[a] = fit.atom_weights.get(a, 0.0), fit.atom_bias.get(a, 0.0)
    return Model(layout, dictionary, weights, bias, trained, voxel=settings.voxel,
                 max_cells=settings.max_cells, stride=det.stride,
                 **({"atom_weights": atom_w, "atom_bias": atom_b} if settings.atom_weights else {}))
