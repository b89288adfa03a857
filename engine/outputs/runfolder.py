"""A finished run's output folder as other steps read it (IFC export, edits): the spaces layer and the elements."""
from __future__ import annotations

import json
import os
from typing import Any

from tiles.errors import UserError


def read_run_outputs(folder: str, *, need: tuple[str, ...] = ()) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """``(spaces layer, elements)`` of a run folder; a one-line error when it is not one (also when a file of
    ``need`` is missing)."""
    for name in ("spaces.geojson", "elements.json", *need):
        if not os.path.isfile(os.path.join(folder, name)):
            raise UserError(folder, f"not a finished run folder: no {name}")
    with open(os.path.join(folder, "spaces.geojson")) as f:
        layer = json.load(f)
    with open(os.path.join(folder, "elements.json")) as f:
        elements = json.load(f)
    return layer, elements
