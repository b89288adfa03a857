"""Updating the space parsing from the detected walls (paper 4.2).

Each neighbour edge of the parse is kept where no detected wall covers the connection areas (the faces) of
the two spaces; the connected components of the kept edges are the final spaces (the update only merges).
A pair without a detected wall merges only on evidence (:func:`weigh_evidence`: no strong parse divider, the
faces open in the points, :mod:`engine.spaces.openness`).  Spaces are renumbered in the order of their
smallest old id; ``space_id`` and ``meta/spaces`` are rewritten.  Why and how: ``docs/design/spaces.md``
(the space update).
"""
from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import networkx as nx
import numpy as np

from engine import config
from engine.detection.proposals import SURE
from engine.spaces.alignment import Frame
from engine.spaces.document import DOC, Face, Neighbour, Space, SpaceParse
from tiles.classes import CLASS_CODES
from tiles.tasks import run_tasks

WALL = CLASS_CODES["wall"]


@dataclass(frozen=True)
class UpdateSettings:
    """When a detected wall separates two neighbouring spaces (see the module docstring)."""

    coverage: float = 0.5
    distance: float = 0.15
    max_angle: float = 20.0
    min_height: float = 0.5
    evidence: bool = True  # merge only across faces shown open (engine.spaces.openness); False: the paper's rule
    divider_share: float = 0.5  # faces with a strong parse divider over this share of the pair's faces stay divided
    strong_score: float = 3.0  # a peak-gap-peak divider at least this strong is strong (other kinds always are)

    def __post_init__(self) -> None:
        if not 0 < self.coverage <= 1:
            raise ValueError(f"coverage must be in (0, 1], not {self.coverage}")
        if not self.distance >= 0:
            raise ValueError(f"distance must be >= 0 metres, not {self.distance}")
        if not 0 <= self.max_angle <= 90:
            raise ValueError(f"max-angle must be in [0, 90] degrees, not {self.max_angle}")
        if not 0 <= self.min_height <= 1:
            raise ValueError(f"min-height must be in [0, 1], not {self.min_height}")
        if not 0 < self.divider_share <= 1:
            raise ValueError(f"divider-share must be in (0, 1], not {self.divider_share}")

    @classmethod
    def from_config(cls, **overrides: Any) -> UpdateSettings:
        """``buildingparser.space-update.*`` with keyword overrides (None = use the setting)."""
        c = config.settings_fields(cls, "space-update")
        c.update({k: v for k, v in overrides.items() if v is not None})
        return cls(**c)


def wall_boxes(walls: Sequence[Any]) -> np.ndarray:
    """``(n, 7)`` ``[cx, cy, cz, dx, dy, dz, yaw]`` of the walls among Proposals or ``elements.json`` records.

    A wall added at a side of its space because the space ends there (``extra[SURE]``,
    :mod:`engine.detection.sides`) is no evidence that it ends there: it is left out."""
    rows = []
    for w in walls:
        if isinstance(w, dict):
            code = int(w.get("class_code", CLASS_CODES.get(str(w.get("class", "")), -1)))
            box = [*w["center"], *w["size"], float(w.get("yaw", 0.0))]
            sure = bool(w.get("extra", {}).get(SURE))
        else:
            code = int(w.class_code)
            box = [*w.center, *w.world_size, float(w.yaw)]
            sure = bool(w.extra.get(SURE))
        if code == WALL and not sure:
            rows.append(box)
    return np.asarray(rows, dtype=np.float64).reshape(-1, 7)


def face_coverage(face: Face, walls: np.ndarray, frame: Frame, params: UpdateSettings) -> float:
    """Length (metres) of ``face`` covered by the walls ``(n, 7)``, overlapping pieces counted once."""
    a0, a1 = float(face.extent[0]), float(face.extent[1])
    if a1 <= a0 or len(walls) == 0:
        return 0.0
    normal = 0 if face.axis == "u" else 1  # the face is normal to this aligned axis and runs along the other
    along = 1 - normal
    centre = frame.to_aligned(walls[:, :2])
    yaw = walls[:, 6] - frame.yaw
    c, s = np.cos(yaw), np.sin(yaw)
    hx, hy = walls[:, 3] / 2, walls[:, 4] / 2
    # half extents of the rotated footprint along the aligned axes
    half = np.stack([np.abs(c) * hx + np.abs(s) * hy, np.abs(s) * hx + np.abs(c) * hy], axis=1)
    # direction of each wall's long axis, and its angle to the face's direction
    long_angle = np.where(walls[:, 3] >= walls[:, 4], yaw, yaw + np.pi / 2)
    face_angle = 0.0 if along == 0 else np.pi / 2
    diff = np.abs((long_angle - face_angle + np.pi / 2) % np.pi - np.pi / 2)
    parallel = diff <= math.radians(params.max_angle) + 1e-9
    # thickness across the face: the short side projected on the normal (not the rotated hull)
    thick = np.where(walls[:, 3] >= walls[:, 4], walls[:, 4], walls[:, 3]) / 2
    across = np.abs(centre[:, normal] - float(face.position)) <= thick + params.distance + 1e-9
    z0, z1 = float(face.z_range[0]), float(face.z_range[1])
    wz0, wz1 = walls[:, 2] - walls[:, 5] / 2, walls[:, 2] + walls[:, 5] / 2
    zover = np.clip(np.minimum(z1, wz1) - np.maximum(z0, wz0), 0, None)
    tall = zover >= params.min_height * max(z1 - z0, 1e-9) - 1e-9
    lo = np.maximum(centre[:, along] - half[:, along], a0)
    hi = np.minimum(centre[:, along] + half[:, along], a1)
    ok = parallel & across & tall & (hi > lo)
    return _union_length(lo[ok], hi[ok])


def _union_length(lo: np.ndarray, hi: np.ndarray) -> float:
    """Total length of the union of intervals ``[lo, hi]``."""
    if len(lo) == 0:
        return 0.0
    order = np.argsort(lo, kind="stable")
    total, cur_lo, cur_hi = 0.0, float(lo[order[0]]), float(hi[order[0]])
    for i in order[1:]:
        if lo[i] > cur_hi:
            total += cur_hi - cur_lo
            cur_lo, cur_hi = float(lo[i]), float(hi[i])
        else:
            cur_hi = max(cur_hi, float(hi[i]))
    return total + cur_hi - cur_lo


def strong_divider(face: Face, params: UpdateSettings) -> bool:
    """The parse's own evidence at the face is strong: a void (empty run), a ridge, a ceiling step, or a
    peak-gap-peak divider scoring at least ``strong_score``."""
    if not face.divider:
        return False
    return face.divider_kind != "peak-gap-peak" or float(face.score or 0.0) >= params.strong_score


def separated_pairs(parse: SpaceParse, walls: Sequence[Any],
                    params: UpdateSettings | None = None) -> dict[tuple[int, int], dict[str, Any]]:
    """Every neighbour pair ``(a, b)``, ``a < b``: face length, wall-covered length, and whether a wall separates them."""
    params = params or UpdateSettings.from_config()
    boxes = walls if isinstance(walls, np.ndarray) else wall_boxes(walls)
    out: dict[tuple[int, int], dict[str, Any]] = {}
    for s in parse.spaces:
        for nb in s.neighbours:
            if nb.space <= s.id:
                continue
            length = float(sum(f.extent[1] - f.extent[0] for f in nb.faces))
            covered = float(sum(face_coverage(f, boxes, parse.frame if getattr(f, "yaw", None) is None
                                              else Frame(f.yaw, parse.frame.origin), params) for f in nb.faces))
            divided = float(sum(f.extent[1] - f.extent[0] for f in nb.faces if strong_divider(f, params)))
            out[(s.id, nb.space)] = {"length": length, "covered": covered,
                                     "wall": length > 0 and covered >= params.coverage * length - 1e-9,
                                     "divider_share": divided / length if length > 0 else 0.0}
    return out


def weigh_evidence(store, parse: SpaceParse, pairs: dict[tuple[int, int], dict[str, Any]], client=None,
                   params: UpdateSettings | None = None) -> dict[tuple[int, int], dict[str, Any]]:
    """Decide ``merge`` for every pair: no detected wall, weak divider evidence, and faces shown open.

    A pair with a detected wall stays apart (the paper's rule); a pair whose faces are mostly parse
    dividers (``divider_share``) stays apart whatever detection says; the others merge only when the
    points across their faces without a divider are continuous (:func:`engine.spaces.openness.faces_open`).
    With ``evidence`` off every pair without a wall merges (the paper's rule alone).
    """
    from engine.spaces.openness import OpennessSettings, faces_open

    params = params or UpdateSettings.from_config()
    if not params.evidence:
        for v in pairs.values():
            v["merge"], v["reason"] = not v["wall"], "wall" if v["wall"] else "no wall"
        return pairs
    faces: list[Face] = []
    owner: list[tuple[int, int]] = []
    for s in parse.spaces:
        for nb in s.neighbours:
            key = (s.id, nb.space)
            v = pairs.get(key)
            if v is None or v["wall"] or v["divider_share"] >= params.divider_share:
                continue
            for f in nb.faces:
                if not strong_divider(f, params):
                    faces.append(f)
                    owner.append(key)
    ev = faces_open(store, parse.frame, faces, client=client)
    seen: dict[tuple[int, int], list[int]] = defaultdict(lambda: [0, 0, 0])
    for key, e in zip(owner, ev):
        acc = seen[key]
        acc[0] += e.get("slices", 0)
        acc[1] += e.get("open_slices", 0)
        acc[2] += 0 if e["open"] or e.get("reason") != "height step" else 1
    for key, v in pairs.items():
        if v["wall"]:
            v["merge"], v["reason"] = False, "wall"
        elif v["divider_share"] >= params.divider_share:
            v["merge"], v["reason"] = False, "divider"
        else:
            n, k, steps = seen.get(key, [0, 0, 0])
            v["open_slices"], v["seen_slices"] = k, n
            ok = n > 0 and steps == 0 and k >= OpennessSettings().min_open * n
            v["merge"], v["reason"] = ok, "open" if ok else ("height step" if steps else "not shown open")
    return pairs


def merge_mapping(space_ids: Sequence[int], pairs: dict[tuple[int, int], dict[str, Any]]) -> dict[int, int]:
    """Old id -> new id: connected components of the pairs to merge (``merge``, else: without a wall),
    numbered by their smallest old id."""
    g = nx.Graph()
    g.add_nodes_from(int(s) for s in space_ids)
    g.add_edges_from(k for k, v in pairs.items() if v.get("merge", not v["wall"]))
    comps = sorted((sorted(c) for c in nx.connected_components(g)), key=lambda c: c[0])
    return {old: new for new, comp in enumerate(comps) for old in comp}


def _rewrite_tile(tile: str, store, lookup: np.ndarray) -> int:
    """One tile's task: map its ``space_id`` through ``lookup`` (index old id + 1) and write the array whole."""
    old = store.read(tile, ["space_id"])["space_id"].astype(np.int64)
    new = lookup[np.clip(old + 1, 0, len(lookup) - 1)]
    new = np.where((old < -1) | (old + 1 >= len(lookup)), old, new).astype(np.int32)
    store.write_array(tile, "space_id", new)
    return int(np.count_nonzero(new != old))


def merge_parse(parse: SpaceParse, mapping: dict[int, int]) -> SpaceParse:
    """The parse with its spaces merged by ``mapping`` (cells, footprints, counts, neighbours recomputed)."""
    import shapely
    from shapely.geometry import mapping as geo_mapping
    from shapely.geometry import shape

    groups: dict[int, list[Space]] = defaultdict(list)
    for s in parse.spaces:
        groups[mapping[s.id]].append(s)
    faces: dict[tuple[int, int], list[Face]] = defaultdict(list)
    for s in parse.spaces:
        for nb in s.neighbours:
            a, b = mapping[s.id], mapping[nb.space]
            if a != b:
                faces[(a, b)].extend(nb.faces)
    spaces = []
    for new in sorted(groups):
        members = groups[new]
        if len(members) == 1:
            fp, area = members[0].footprint, members[0].area_m2
        else:
            geoms = [shape(m.footprint) for m in members if m.footprint and m.footprint.get("coordinates")]
            union = shapely.set_precision(shapely.union_all(geoms), 1e-4) if geoms else None
            fp = geo_mapping(union) if union is not None else {"type": "Polygon", "coordinates": []}
            fp = _plain(fp)
            area = float(sum(m.area_m2 for m in members))
        nbs = [Neighbour(o, list(faces[(new, o)])) for o in sorted({o for (a, o) in faces if a == new})]
        spaces.append(Space(new, min(m.floor for m in members), sorted(c for m in members for c in m.cells), fp,
                            area, [min(m.z_range[0] for m in members), max(m.z_range[1] for m in members)],
                            int(sum(m.point_count for m in members)),
                            sorted({t for m in members for t in m.tiles}), nbs))
    cells = [replace(c, space=mapping.get(c.space, c.space) if c.space >= 0 else c.space) for c in parse.cells]
    return replace(parse, spaces=spaces, cells=cells, stats=dict(parse.stats))


def _plain(x: Any) -> Any:
    """GeoJSON from shapely (tuples) as plain lists."""
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    return float(x) if isinstance(x, (float, np.floating)) else x


def update_spaces(store, parse: SpaceParse, walls: Sequence[Any], client=None, *,
                  params: UpdateSettings | None = None, truth: str | None = "gt_space"
                  ) -> tuple[SpaceParse, dict[int, int]]:
    """Merge neighbouring spaces with no detected wall between them; rewrite ``space_id`` and ``meta/spaces``.

    Parameters
    ----------
    store
        The :class:`tiles.store.TileStore` whose ``space_id`` arrays ``parse`` describes.
    parse
        The space parsing (:class:`engine.spaces.parse.SpaceParse`, e.g. ``SpaceParse.load(store)``).
    walls
        Detected elements after the CRF (Proposals or ``elements.json`` records); only walls are used.
    client
        A ``distributed.Client``; None rewrites the tiles here.
    params
        None reads ``buildingparser.space-update.*``.
    truth
        A per-point ground-truth array; when the store has it, the ARI against it before and after
        the update (:func:`engine.metrics.ari.distributed_ari`) goes to ``stats["space_update"]``.

    Returns
    -------
    new_parse, mapping
        The updated parse (also stored as ``meta/spaces``) and old id -> new id for every space.
    """
    params = params or UpdateSettings.from_config()
    boxes = wall_boxes(walls)
    pairs = weigh_evidence(store, parse, separated_pairs(parse, boxes, params), client, params)
    mapping = merge_mapping([s.id for s in parse.spaces], pairs)
    has_truth = bool(truth) and truth in store.meta.names() and "space_id" in store.meta.names()
    record: dict[str, Any] = {"walls": int(len(boxes)), "pairs": len(pairs),
                              "separated": int(sum(v["wall"] for v in pairs.values())),
                              "kept": {r: int(sum(v["reason"] == r for v in pairs.values()))
                                       for r in ("wall", "divider", "height step", "not shown open")},
                              "merges": int(len(parse.spaces) - len(set(mapping.values()))), "splits": 0,
                              "spaces_before": len(parse.spaces), "spaces_after": len(set(mapping.values())),
                              "params": {"coverage": params.coverage, "distance": params.distance,
                                         "max_angle": params.max_angle, "min_height": params.min_height,
                                         "evidence": params.evidence, "divider_share": params.divider_share,
                                         "strong_score": params.strong_score},
                              "merged": {str(k): v for k, v in mapping.items() if k != v}}
    if has_truth:
        from engine.metrics.ari import distributed_ari

        record["ari_before"] = distributed_ari(store, truth=truth, pred="space_id", client=client)
    changed = any(k != v for k, v in mapping.items())
    if changed:
        top = max(mapping)
        lookup = np.arange(-1, top + 1, dtype=np.int64)  # lookup[old + 1]; ids absent from the parse stay
        for old, new in mapping.items():
            lookup[old + 1] = new
        tiles = [t.name for t in store.tiles]
        moved = run_tasks(_rewrite_tile, tiles, client=client, label="space update: rewriting space_id", keys=tiles,
                          extra_args=(store, lookup))
        record["points_relabelled"] = int(sum(moved))
        new_parse = merge_parse(parse, mapping)
    else:
        record["points_relabelled"] = 0
        new_parse = replace(parse, stats=dict(parse.stats))
    if has_truth:
        record["ari_after"] = distributed_ari(store, truth=truth, pred="space_id", client=client) if changed \
            else record["ari_before"]
    new_parse.stats["space_update"] = record
    store.set_doc(DOC, new_parse.to_doc())
    return new_parse, mapping


def update_summary(parsed: SpaceParse, final: SpaceParse, elements: dict[str, Any] | None = None) -> dict[str, Any]:
    """What the update did, for ``metrics.json`` and the report: merges, splits, why pairs were kept apart."""
    rec = final.stats.get("space_update") if final is not parsed else None
    out: dict[str, Any] = {"enabled": rec is not None, "spaces_before": len(parsed.spaces),
                           "spaces_after": len(final.spaces), "merges": len(parsed.spaces) - len(final.spaces),
                           "splits": 0}
    if rec:
        out.update(pairs=rec.get("pairs"), walls=rec.get("walls"), kept=rec.get("kept"),
                   evidence=(rec.get("params") or {}).get("evidence", False))
    if elements is not None:
        out["elements"] = {k: v for k, v in elements.items() if k != "removed"}
    return out
