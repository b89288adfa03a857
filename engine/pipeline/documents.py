"""What a run keeps in the store's documents between its stages, and the maps between cells, parsed and final spaces.

The parsed spaces (before the space update), the detection proposals and the
elements kept by the CRF are stored documents, so a rerun can skip the stages
that made them.  A redone stage that reads the parsed spaces first undoes an
earlier run's space update (:func:`restore_parsed`).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from tiles.store import TileStore

SPACES_PARSED_DOC = "spaces_parsed"
PROPOSALS_DOC = "proposals"
ELEMENTS_DOC = "elements"


def renumber(elements: list) -> list:
    """Element ids 0..n-1 by space, class and decreasing score (stable for a given input)."""
    elements = sorted(elements, key=lambda e: (int(e.space_id), int(e.class_code), -float(e.score)))
    for i, e in enumerate(elements):
        e.element_id = i
    return elements


def save_proposals(store: TileStore, doc: str, proposals: list, **extra: Any) -> None:
    """Store proposals (or elements) as the document ``doc``, with ``extra`` keys beside them."""
    from engine.detection.proposals import proposal_to_json

    store.set_doc(doc, {"proposals": [proposal_to_json(p) for p in proposals], **extra})


def load_proposals(store: TileStore, doc: str) -> list:
    """The proposals of document ``doc`` (none when it is missing)."""
    from engine.detection.proposals import proposal_from_json

    return [proposal_from_json(d) for d in (store.doc(doc) or {}).get("proposals", [])]


def space_lookup(parsed, final) -> dict[int, int]:
    """Parsed space id -> final space id (final spaces are unions of parsed ones)."""
    cell_final = {c: s.id for s in final.spaces for c in s.cells}
    out = {}
    for s in parsed.spaces:
        targets = {cell_final.get(c) for c in s.cells} - {None}
        out[s.id] = min(targets) if targets else s.id
    return out


def cell_lookup(parse) -> np.ndarray:
    """``lut[cell_id + 1]`` = the space of that cell (-1 for cell -1)."""
    n = max((c.id for c in parse.cells), default=-1) + 2
    lut = np.full(n, -1, dtype=np.int32)
    for c in parse.cells:
        lut[c.id + 1] = c.space
    for s in parse.spaces:
        for c in s.cells:
            lut[c + 1] = s.id
    return lut


def _restore_tile(tile: str, store: TileStore, lut: np.ndarray) -> int:
    cell = store.read(tile, ["cell_id"])["cell_id"]
    store.write_array(tile, "space_id", lut[cell.astype(np.int64) + 1])
    return len(cell)


def restore_parsed(store: TileStore, parsed, client) -> None:
    """Undo an earlier run's space update, so a redone stage starts from the parsed spaces."""
    from engine.spaces.document import DOC
    from tiles.tasks import run_tasks

    if store.doc(DOC) == store.doc(SPACES_PARSED_DOC):
        return
    lut = cell_lookup(parsed)
    run_tasks(_restore_tile, [t.name for t in store.tiles], client=client, label="restoring parsed spaces",
              extra_args=(store, lut))
    store.set_doc(DOC, parsed.to_doc())
