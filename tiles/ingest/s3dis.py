"""The raw S3DIS layout: ``Area_N/<room>/Annotations/<class>_<i>.txt``, rooms as ground-truth spaces.

Accepted: an area folder, a folder of areas, or a single room folder (a folder
with an ``Annotations/`` sub-folder), in natural order.  The points are read
once, from the annotation files (one element instance, one class each); room
files are only counted, and read as clutter for a room without annotations.
Which points are the input, the labels and the ground-truth document:
docs/design/tiles.md, "The raw S3DIS layout".
"""
from __future__ import annotations

import hashlib
import re
from collections import defaultdict
from collections.abc import Iterator
from typing import Any

import numpy as np

from tiles import paths
from tiles.classes import CLASS_CODES, CLASS_NAMES, CLUTTER
from tiles.config import setting
from tiles.errors import UserError
from tiles.groundtruth import GTElement, GTSpace, gt_dimensions
from tiles.ingest.files import file_size, is_dir, listdir, open_binary
from tiles.ingest.lines import BlockStats
from tiles.ingest.reader import PartResult, Quantization, Reader
from tiles.ingest.text import (
    Sniff,
    bad_line_policy,
    color_dimensions,
    defect_warnings,
    line_number,
    parse_lines,
    points_columns,
    read_lines_block,
    sniff,
)
from tiles.schema import coordinate_dimensions

_ANNOTATION = re.compile(r"^(?P<cls>.+?)_(?P<num>\d+)(?P<dup> \(\d+\))?\.txt$")


def natural_key(name: str) -> list:
    """Sort key that puts ``office_2`` before ``office_10``."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


def _is_room(path: str, so) -> bool:
    return any(name == "Annotations" and d for name, d in listdir(path, so))


def _rooms_of(path: str, so) -> list[str]:
    return [name for name, d in listdir(path, so) if d and not name.startswith(".")
            and _is_room(paths.join(path, name), so)]


def find_areas(path: str, storage_options=None) -> list[tuple[str, list[str]]]:
    """``(area folder, room names)`` of an S3DIS folder (area, folder of areas, or one room)."""
    if not is_dir(path, storage_options):
        raise UserError(path, "no such folder")
    if _is_room(path, storage_options):
        parent, name = path.rstrip("/").rsplit("/", 1) if "/" in path else (".", path)
        return [(parent, [name])]
    rooms = _rooms_of(path, storage_options)
    if rooms:
        return [(path, sorted(rooms, key=natural_key))]
    areas = []
    for name, d in sorted(listdir(path, storage_options), key=lambda e: natural_key(e[0])):
        if d and not name.startswith("."):
            sub = paths.join(path, name)
            r = _rooms_of(sub, storage_options)
            if r:
                areas.append((sub, sorted(r, key=natural_key)))
    if not areas:
        raise UserError(path, "a folder but not an S3DIS area or a folder of areas "
                              "(no <room>/Annotations/ folders inside)")
    return areas


def space_type(room: str) -> str:
    """``office_12`` -> ``office``; ``copyRoom_1`` -> ``copyRoom``."""
    return re.sub(r"_\d+$", "", room)


def _same_content(a: str, b: str, so) -> bool:
    digests = []
    for p in (a, b):
        h = hashlib.blake2b()
        with open_binary(p, so) as f:
            while piece := f.read(1 << 22):
                h.update(piece)
        digests.append(h.digest())
    return digests[0] == digests[1]


def _count_lines(path: str, so) -> int:
    n, last = 0, b"\n"
    with open_binary(path, so) as f:
        while piece := f.read(1 << 24):
            n += piece.count(b"\n")
            last = piece[-1:]
    return n + (last != b"\n")


class S3DISReader(Reader):
    """One S3DIS area (or one room) as one source."""

    format = "s3dis"

    def __init__(self, area: str, rooms: list[str], storage_options: dict[str, Any] | None = None):
        self.path = area
        self.storage_options = storage_options
        self.area_name = area.rstrip("/").rsplit("/", 1)[-1]
        self.dimensions = coordinate_dimensions() + color_dimensions() + gt_dimensions()
        self.policy = bad_line_policy()
        self.check_rooms = setting("ingest.s3dis.check-room-files")
        self.space_base = 0
        self.instance_base = 0
        #: per room: name, room file (or None), [(path, size, class name, class code)]
        self.rooms: list[dict[str, Any]] = []
        self.notes: dict[str, Any] = {"duplicate_files_skipped": [], "duplicate_files_kept": [],
                                      "other_classes": defaultdict(int), "ignored_files": []}
        so = storage_options
        for room in rooms:
            rdir = paths.join(area, room)
            entries = listdir(rdir, so)
            txts = [n for n, d in entries if not d and n.endswith(".txt") and not n.startswith(".")]
            room_file = f"{room}.txt" if f"{room}.txt" in txts else (txts[0] if txts else None)
            ann_dir = paths.join(rdir, "Annotations")
            ann = [(n, d) for n, d in listdir(ann_dir, so)]
            names = {n for n, d in ann if not d}
            files = []
            for name, d in sorted(ann, key=lambda e: natural_key(e[0])):
                if d or name.startswith(".") or not name.endswith(".txt"):
                    self.notes["ignored_files"].append(f"{room}/Annotations/{name}")
                    continue
                m = _ANNOTATION.match(name)
                cls = (m.group("cls") if m else name[:-4]).strip()
                fpath = paths.join(ann_dir, name)
                if m and m.group("dup"):
                    original = f"{m.group('cls')}_{m.group('num')}.txt"
                    if original in names and _same_content(fpath, paths.join(ann_dir, original), so):
                        self.notes["duplicate_files_skipped"].append(
                            {"file": f"{room}/Annotations/{name}", "lines": _count_lines(fpath, so)})
                        continue
                    self.notes["duplicate_files_kept"].append(f"{room}/Annotations/{name}")
                code = CLASS_CODES.get(cls.lower(), CLUTTER)
                if cls.lower() not in CLASS_CODES:
                    self.notes["other_classes"][cls] += 1
                files.append((fpath, self._size(fpath), CLASS_NAMES[code], code))
            self.rooms.append({"name": room, "room_file": paths.join(rdir, room_file) if room_file else None,
                               "files": files})
        if not any(r["files"] or r["room_file"] for r in self.rooms):
            raise UserError(area, "empty point cloud: no annotation or room files")
        first = next((f[0] for r in self.rooms for f in r["files"]), None) or \
            next(r["room_file"] for r in self.rooms if r["room_file"])
        self.layout = sniff(first, so, allowed=(6,))
        self.instance_count = sum(len(r["files"]) for r in self.rooms)
        self.space_count = len(self.rooms)

    def _size(self, p: str) -> int:
        return file_size(p, self.storage_options)

    def set_id_base(self, space: int, instance: int) -> None:
        """Number this area's spaces and instances after those of earlier sources."""
        self.space_base, self.instance_base = space, instance

    def first_point(self) -> np.ndarray:
        return self.layout.point

    # -- plan: segments of files grouped into parts of about part_points lines ---------------------
    def _segments(self, step: int) -> Iterator[tuple]:
        inst = self.instance_base
        for k, room in enumerate(self.rooms):
            space = self.space_base + k
            if not room["files"] and room["room_file"]:
                size = file_size(room["room_file"], self.storage_options)
                for s in range(0, max(size, 1), step):
                    yield (room["room_file"], size, s, min(s + step, size), space, -1, CLUTTER)
                continue
            for fpath, size, _, code in room["files"]:
                for s in range(0, max(size, 1), step):
                    yield (fpath, size, s, min(s + step, size), space, inst, code)
                inst += 1

    def plan(self, part_points: int) -> list[Any]:
        step = max(1024, int(part_points * self.layout.bytes_per_line))
        specs, cur, used = [], [], 0
        for seg in self._segments(step):
            cur.append(seg)
            used += seg[3] - seg[2]
            if used >= step:
                specs.append(("points", cur))
                cur, used = [], 0
        if cur:
            specs.append(("points", cur))
        if self.check_rooms:
            rooms = [(self.space_base + k, r["room_file"]) for k, r in enumerate(self.rooms)
                     if r["files"] and r["room_file"]]
            for i in range(0, len(rooms), 64):
                specs.append(("count", rooms[i:i + 64]))
        return specs

    def parts_of(self, spec: Any) -> int:
        return 1 if spec[0] == "points" else 0

    def read(self, spec: Any, grid: Quantization) -> Iterator[PartResult]:
        kind, items = spec
        if kind == "count":
            yield PartResult({}, {"room_lines": {str(space): _count_lines(p, self.storage_options)
                                                 for space, p in items}})
            return
        cols_list, segs, block_stats = [], [], []
        so = self.storage_options
        layout = Sniff(0, 6, " ", 0, self.layout.point, self.layout.bytes_per_line)
        for fpath, size, start, end, space, inst, code in items:
            with open_binary(fpath, so) as f:
                begin, buf = read_lines_block(f, start, end, 0, size)
            vals, st = parse_lines(fpath, so, buf, begin, layout, self.policy)
            cols = points_columns(fpath, so, vals, begin, st, grid)
            n = len(vals)
            cols["gt_space"] = np.full(n, space, dtype=np.int32)
            cols["gt_class"] = np.full(n, code, dtype=np.uint8)
            cols["gt_instance"] = np.full(n, inst, dtype=np.int32)
            cols_list.append(cols)
            seg = _segment_stats(vals[:, :3], space, inst, code)
            seg["lines"] = n + st.blank + st.skipped_control + st.skipped_bad
            segs.append(seg)
            block_stats.append((fpath, begin, st))
        columns = {k: np.concatenate([c[k] for c in cols_list]) for k in cols_list[0]}
        stats = _merge_block_stats(block_stats)
        stats["segments"] = segs
        yield PartResult(columns, stats)

    # -- reporting --------------------------------------------------------------------------
    def source_info(self, stats: list[dict[str, Any]]) -> dict[str, Any]:
        info = {k: int(sum(s.get(k, 0) for s in stats)) for k in
                ("blank_lines", "repaired_lines", "skipped_control_lines", "skipped_bad_lines")}
        examples = [e for s in stats for e in s.get("examples", [])][:5]
        if examples:
            info["defects"] = [f"{_rel(self.path, p)} line {line_number(p, self.storage_options, pos)}: {w}"
                               for p, pos, w in examples]
        info["rooms"] = len(self.rooms)
        info["annotation_files"] = self.instance_count
        info["input"] = "annotation files (the room files are their concatenation)"
        n = self.notes
        if n["duplicate_files_skipped"]:
            info["duplicate_files_skipped"] = n["duplicate_files_skipped"]
        if n["duplicate_files_kept"]:
            info["duplicate_files_kept"] = n["duplicate_files_kept"]
        if n["other_classes"]:
            info["other_classes_as_clutter"] = dict(n["other_classes"])
        if n["ignored_files"]:
            info["ignored_files"] = n["ignored_files"]
        lines_per_space: dict[int, int] = defaultdict(int)
        for s in stats:
            for seg in s.get("segments", []):
                lines_per_space[seg["space"]] += seg["lines"]
        room_lines: dict[str, int] = {}
        for s in stats:
            room_lines.update(s.get("room_lines", {}))
        mismatched = []
        for k, room in enumerate(self.rooms):
            sid = self.space_base + k
            if str(sid) in room_lines and room_lines[str(sid)] != lines_per_space.get(sid, 0):
                mismatched.append({"room": room["name"], "room_file_lines": room_lines[str(sid)],
                                   "annotation_lines": lines_per_space.get(sid, 0)})
        if mismatched:
            info["room_file_mismatch"] = mismatched
        no_ann = [r["name"] for r in self.rooms if not r["files"]]
        if no_ann:
            info["rooms_without_annotations"] = no_ann
        return info

    def warnings(self, info: dict[str, Any]) -> list[str]:
        out = defect_warnings(self.path, info)
        if info.get("duplicate_files_skipped"):
            d = info["duplicate_files_skipped"]
            out.append(f"{self.path}: skipped {len(d)} duplicated annotation file(s) identical to their original "
                       f"({sum(x['lines'] for x in d)} lines), e.g. {d[0]['file']}")
        if info.get("duplicate_files_kept"):
            out.append(f"{self.path}: {len(info['duplicate_files_kept'])} annotation file(s) named as duplicates "
                       f"differ from their original and were read as instances of their own, e.g. "
                       f"{info['duplicate_files_kept'][0]}")
        if info.get("other_classes_as_clutter"):
            out.append(f"{self.path}: annotation classes outside the 13 read as clutter: "
                       + ", ".join(f"{k} ({v} file(s))" for k, v in info["other_classes_as_clutter"].items()))
        if info.get("room_file_mismatch"):
            m = info["room_file_mismatch"][0]
            out.append(f"{self.path}: {len(info['room_file_mismatch'])} room file(s) do not hold as many lines as "
                       f"their annotation files, e.g. {m['room']}: {m['room_file_lines']} vs {m['annotation_lines']}")
        if info.get("rooms_without_annotations"):
            out.append(f"{self.path}: rooms without annotation files read from their room file as clutter: "
                       + ", ".join(info["rooms_without_annotations"][:5]))
        return out

    def ground_truth(self, stats: list[dict[str, Any]], grid: Quantization) -> tuple[list[GTSpace], list[GTElement]]:
        """Spaces and element boxes of this area from the parts' segment statistics."""
        by_inst: dict[int, list[dict]] = defaultdict(list)
        by_space: dict[int, list[dict]] = defaultdict(list)
        for s in stats:
            for seg in s.get("segments", []):
                if seg["count"]:
                    by_space[seg["space"]].append(seg)
                    if seg["instance"] >= 0:
                        by_inst[seg["instance"]].append(seg)
        spaces = []
        for k, room in enumerate(self.rooms):
            sid = self.space_base + k
            segs = by_space.get(sid, [])
            if not segs:
                continue
            lo = np.min([s["min"] for s in segs], axis=0)
            hi = np.max([s["max"] for s in segs], axis=0)
            hull = _hull(np.concatenate([np.asarray(s["hull"], dtype=np.float64).reshape(-1, 2) for s in segs]))
            spaces.append(GTSpace(sid, room["name"], space_type(room["name"]), 0,
                                  [[round(x, 4), round(y, 4)] for x, y in hull],
                                  [round(float(lo[2]), 4), round(float(hi[2]), 4)]))
        elements = []
        for inst in sorted(by_inst):
            segs = by_inst[inst]
            lo = np.min([s["min"] for s in segs], axis=0)
            hi = np.max([s["max"] for s in segs], axis=0)
            code = segs[0]["class"]
            elements.append(GTElement(inst, CLASS_NAMES[code], code, segs[0]["space"],
                                      [round(float(v), 4) for v in (lo + hi) / 2],
                                      [round(float(v), 4) for v in hi - lo], 0.0))
        return spaces, elements


def _segment_stats(xyz: np.ndarray, space: int, inst: int, code: int) -> dict[str, Any]:
    n = len(xyz)
    if not n:
        return {"space": space, "instance": inst, "class": code, "count": 0}
    return {"space": space, "instance": inst, "class": code, "count": n,
            "min": xyz.min(axis=0).tolist(), "max": xyz.max(axis=0).tolist(),
            "hull": _hull(xyz[:, :2]).tolist()}


def _hull(xy: np.ndarray) -> np.ndarray:
    """Vertices of the XY convex hull (counter-clockwise); the points themselves when degenerate."""
    from scipy.spatial import ConvexHull, QhullError

    xy = np.unique(np.asarray(xy, dtype=np.float64), axis=0)
    if len(xy) < 3:
        return xy
    try:
        return xy[ConvexHull(xy).vertices]
    except QhullError:
        lo, hi = xy.min(axis=0), xy.max(axis=0)
        return np.array([lo, hi])


def _merge_block_stats(blocks: list[tuple[str, int, BlockStats]]) -> dict[str, Any]:
    out = {"blank_lines": 0, "repaired_lines": 0, "skipped_control_lines": 0, "skipped_bad_lines": 0,
           "examples": []}
    for path, begin, st in blocks:
        j = st.to_json()
        for k in ("blank_lines", "repaired_lines", "skipped_control_lines", "skipped_bad_lines"):
            out[k] += j[k]
        out["examples"].extend((path, begin + p, w) for p, w in st.examples)
    out["examples"] = out["examples"][:5]
    return out


def _rel(root: str, p: str) -> str:
    return p[len(root):].lstrip("/") if p.startswith(root) else p


def readers_for(path: str, storage_options=None) -> list[S3DISReader]:
    """One reader per area found under ``path``."""
    return [S3DISReader(area, rooms, storage_options) for area, rooms in find_areas(path, storage_options)]


__all__ = ["S3DISReader", "find_areas", "readers_for", "space_type"]
