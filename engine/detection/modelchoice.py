"""Which shipped detection model a run uses: the colour-free one for a cloud without colour (issue 25 item 4).

The shipped default model reads colour (the ``color`` and ``context_color`` feature groups); on a cloud
without colour those columns are zero or one constant, values it never saw in training.  The colour-free
model (``engine/models/nocolour``, ``make model``: the same buildings and seeds, and two with the appearance
difficulties of real scans, with ``train --no-colour``) has both groups disabled, so nothing in it reads a
point's colour.  :func:`choose_model` picks it from the tile store's metadata after ingest
(:attr:`tiles.schema.StoreMeta.color_constant`): the store has no colour dimensions, or every point has the
same colour.  The setting ``buildingparser.detection.colour-free-model``:
``auto`` (that rule), ``always``, ``never``; a model given by the user (``--model``) always wins.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

from engine.detection.model import default_model_path

#: Values of ``buildingparser.detection.colour-free-model``.
COLOUR_FREE_MODES = ("auto", "always", "never")
#: The colour-free model's file stem beside the default model.
COLOUR_FREE_NAME = "nocolour"
#: The feature groups that read colour (all disabled in the colour-free model).
COLOUR_GROUPS = ("color", "context_color")


def colour_free_model_path() -> str:
    """The shipped colour-free model (``engine/models/nocolour``)."""
    return os.path.join(os.path.dirname(default_model_path()), COLOUR_FREE_NAME)


@dataclass(frozen=True)
class ModelChoice:
    """The model a run uses and why.

    Parameters
    ----------
    path
        The model's path (stem); None: the shipped default.
    name
        Its name (file stem).
    colour_free
        Whether it is the shipped colour-free model.
    reason
        One sentence: why this model.
    """

    path: str | None
    name: str
    colour_free: bool
    reason: str

    def to_json(self) -> dict[str, Any]:
        """The choice for ``metrics.json`` (``model``)."""
        return {"name": self.name, "colour_free": self.colour_free, "reason": self.reason}


def colour_state(meta: Any) -> str:
    """``"none"`` (no colour dimensions), ``"constant"`` (every point one colour) or ``"varied"`` for a store's
    metadata (:class:`tiles.schema.StoreMeta`; a store written before the constancy was recorded counts as
    varied when it has colour)."""
    names = set(meta.names())
    if not {"red", "green", "blue"} & names:
        return "none"
    return "constant" if meta.color_constant else "varied"


def choose_model(meta: Any, model: str | None = None, mode: str | None = None) -> ModelChoice:
    """The model for a store with metadata ``meta``.

    Parameters
    ----------
    meta
        The tile store's :class:`tiles.schema.StoreMeta`.
    model
        The model the user gave (``--model``); it wins whatever the cloud.
    mode
        ``auto``, ``always`` or ``never``; None: ``buildingparser.detection.colour-free-model``.
    """
    from engine.detection.model import model_stem
    from tiles import config

    if model is not None:
        stem = model_stem(model)
        return ModelChoice(stem, os.path.basename(stem), False, "given with --model")
    mode = str(config.setting("detection.colour-free-model")) if mode is None else mode
    if mode not in COLOUR_FREE_MODES:
        raise ValueError(f"colour-free-model: {mode!r} is not one of {', '.join(COLOUR_FREE_MODES)}")
    state = colour_state(meta)
    if mode == "always":
        return _colour_free("detection.colour-free-model is always")
    if mode == "auto" and state == "none":
        return _colour_free("the cloud has no colour")
    if mode == "auto" and state == "constant":
        return _colour_free("every point of the cloud has the same colour")
    why = {"never": "detection.colour-free-model is never", "auto": "the cloud has colour"}[mode]
    return ModelChoice(None, os.path.basename(default_model_path()), False, why)


def _colour_free(reason: str) -> ModelChoice:
    path = colour_free_model_path()
    if not all(os.path.isfile(path + ext) for ext in (".npz", ".json")):
        return ModelChoice(None, os.path.basename(default_model_path()), False,
                           f"{reason}, but the colour-free model is not installed ({path}.npz/.json)")
    return ModelChoice(path, os.path.basename(path), True, reason)
