"""Plain text point clouds: one point per line, ``x y z`` or ``x y z r g b``, whitespace or comma separated.

Files ending in ``.txt``, ``.xyz``, ``.pts``, ``.csv`` or ``.asc``.  Lines before
the first point line that are not points (a column header such as
``//X Y Z R G B``, the point count line of a ``.pts`` file) are skipped and
counted.  Coordinates are stored on a 0.1 mm grid (``buildingparser.ingest.scale``)
around a round offset near the first point; colours are integers 0-65535
(0-255 for 8-bit colour, scaled to 16 bits on export).

Parts are byte ranges of the file, cut on line boundaries (a line belongs to the
part its first byte falls in), parsed by :func:`tiles.ingest.lines.parse_block`
(repairs of damaged lines there); its errors name the file and line here.
"""
from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from tiles.config import setting
from tiles.errors import UserError
from tiles.ingest.files import check_file, file_size, open_binary
from tiles.ingest.lines import CONTROL, BlockStats, LineError, all_floats, parse_block, tokens
from tiles.ingest.reader import PartResult, Quantization, Reader
from tiles.schema import Dimension, coordinate_dimensions

EXTENSIONS = (".txt", ".xyz", ".pts", ".csv", ".asc")
SNIFF_BYTES = 1 << 16


def color_dimensions() -> list[Dimension]:
    return [Dimension(c, "uint16", "las", f"{c} colour", {"name": c}) for c in ("red", "green", "blue")]


def grid_scale() -> float:
    """The coordinate step of sources without their own (``buildingparser.ingest.scale``)."""
    return setting("ingest.scale")


def bad_line_policy() -> str:
    """What to do with an unreadable line (``buildingparser.ingest.bad-lines``): error or skip."""
    return setting("ingest.bad-lines")


# -- blocks of a file -------------------------------------------------------------------------

def read_lines_block(f, start: int, end: int, first: int, size: int) -> tuple[int, bytes]:
    """The whole lines that start in ``[start, end)`` of a file whose data starts at ``first``:
    ``(position of the first byte, bytes)``."""
    if start > first:
        f.seek(start - 1)
        skip = 0
        while True:
            piece = f.read(SNIFF_BYTES)
            if not piece:
                return size, b""
            j = piece.find(b"\n")
            if j >= 0:
                skip += j + 1
                break
            skip += len(piece)
        begin = start - 1 + skip
    else:
        begin = start
    if begin >= end or begin >= size:
        return begin, b""
    f.seek(begin)
    data = f.read(end - begin)
    if not data.endswith(b"\n") and begin + len(data) < size:
        tail = []
        while True:
            piece = f.read(SNIFF_BYTES)
            if not piece:
                break
            j = piece.find(b"\n")
            if j >= 0:
                tail.append(piece[:j + 1])
                break
            tail.append(piece)
        data += b"".join(tail)
    return begin, data


def line_number(path: str, storage_options, pos: int) -> int:
    """1-based line number of byte ``pos`` (for error messages only: reads the file up to there)."""
    n, done = 0, 0
    with open_binary(path, storage_options) as f:
        while done < pos:
            piece = f.read(min(1 << 24, pos - done))
            if not piece:
                break
            n += piece.count(b"\n")
            done += len(piece)
    return n + 1


@dataclass
class Sniff:
    """What the first bytes of a text file say: where points start, how many columns, the separator."""

    first: int
    ncols: int
    sep: str
    header_lines: int
    point: np.ndarray
    bytes_per_line: float


def sniff(path: str, storage_options=None, allowed=(3, 6)) -> Sniff:
    """Look at the start of a text file (driver side) to learn its layout; clear errors if it has no points."""
    with open_binary(path, storage_options) as f:
        head = f.read(SNIFF_BYTES)
    if not head.strip():
        raise UserError(path, "empty point cloud: the file holds no points")
    lines = head.split(b"\n")
    if len(head) == SNIFF_BYTES and len(lines) > 1:
        lines = lines[:-1]  # the last one may be cut
    pos, header = 0, 0
    for k, line in enumerate(lines):
        toks = tokens(bytes(c for c in line if not CONTROL[c]))
        if toks and len(toks) in allowed and all_floats(toks):
            vals = np.array([float(t) for t in toks])
            if not np.isfinite(vals).all():
                raise UserError(path, f"line {k + 1}: not a finite number (NaN or infinity) in {line[:60]!r}")
            sep = "," if b"," in line else ("\t" if b"\t" in line and b" " not in line else
                                            (" " if re.fullmatch(rb"\S+( \S+)*\r?", line) else r"\s+"))
            n_lines = max(1, len(lines) - k)
            per_line = (len(head) - pos) / n_lines
            return Sniff(pos, len(toks), sep, header, vals[:3], per_line)
        if toks and all_floats(toks) and len(toks) not in allowed and len(toks) > 1:
            raise UserError(path, f"line {k + 1}: {len(toks)} columns; expected "
                                  + " or ".join({3: "x y z", 6: "x y z r g b"}[c] for c in allowed))
        if k >= 20:
            break
        header += 1 if toks else 0
        pos += len(line) + 1
    raise UserError(path, "no point lines (x y z or x y z r g b) at the start of the file")


class TextReader(Reader):
    """A text file of points (local path or fsspec URL)."""

    format = "text"

    def __init__(self, path: str, storage_options: dict[str, Any] | None = None):
        self.path = path
        self.storage_options = storage_options
        check_file(path, storage_options)
        self.size = file_size(path, storage_options)
        self.layout = sniff(path, storage_options)
        self.dimensions = coordinate_dimensions() + (color_dimensions() if self.layout.ncols == 6 else [])
        self.policy = bad_line_policy()

    def first_point(self) -> np.ndarray:
        return self.layout.point

    def plan(self, part_points: int) -> list[Any]:
        step = max(1024, int(part_points * self.layout.bytes_per_line))
        return [(s, min(s + step, self.size)) for s in range(self.layout.first, self.size, step)] or \
            [(self.layout.first, self.size)]

    def read(self, spec: Any, grid: Quantization) -> Iterator[PartResult]:
        start, end = spec
        with open_binary(self.path, self.storage_options) as f:
            begin, buf = read_lines_block(f, start, end, self.layout.first, self.size)
        vals, stats = parse_lines(self.path, self.storage_options, buf, begin, self.layout, self.policy)
        cols = points_columns(self.path, self.storage_options, vals, begin, stats, grid)
        info = stats.to_json()
        info["examples"] = [(begin + p, w) for p, w in stats.examples]
        yield PartResult(cols, info)

    def source_info(self, stats: list[dict[str, Any]]) -> dict[str, Any]:
        info = summarize_defects(self.path, self.storage_options, stats)
        info["header_lines"] = self.layout.header_lines
        info["columns"] = "x y z r g b" if self.layout.ncols == 6 else "x y z"
        return info

    def warnings(self, info: dict[str, Any]) -> list[str]:
        return defect_warnings(self.path, info)


def parse_lines(path: str, storage_options, buf: bytes, begin: int, layout: Sniff, policy: str):
    """:func:`parse_block` with its errors turned into a one-line message naming the file and line."""
    try:
        return parse_block(buf, layout.ncols, layout.sep, policy=policy)
    except LineError as exc:
        raise UserError(path, f"line {line_number(path, storage_options, begin + exc.pos)}: {exc.message}") \
            from None


def points_columns(path: str, storage_options, vals: np.ndarray, begin: int, stats: BlockStats,
                   grid: Quantization) -> dict[str, np.ndarray]:
    """Columns of parsed rows: raw x/y/z on the grid and uint16 colours (checked: integers 0-65535)."""
    cols = grid.quantize(vals[:, :3], path)
    if vals.shape[1] >= 6:
        rgb = vals[:, 3:6]
        ok = (rgb >= 0) & (rgb <= 65535) & (rgb == np.floor(rgb))
        if not ok.all():
            i = int(np.flatnonzero(~ok.all(axis=1))[0])
            raise UserError(path, f"point {i + 1} of the block at byte {begin:,}: colour values "
                                  f"{rgb[i].tolist()} are not integers 0-65535")
        for j, c in enumerate(("red", "green", "blue")):
            cols[c] = rgb[:, j].astype(np.uint16)
    return cols


def summarize_defects(path: str, storage_options, stats: list[dict[str, Any]]) -> dict[str, Any]:
    """Sum the parts' line counts and give line numbers for the first few defects."""
    keys = ("blank_lines", "repaired_lines", "skipped_control_lines", "skipped_bad_lines")
    info: dict[str, Any] = {k: int(sum(s.get(k, 0) for s in stats)) for k in keys}
    examples = [e for s in stats for e in s.get("examples", [])][:5]
    if examples:
        info["defects"] = [f"line {line_number(path, storage_options, pos)}: {what}" for pos, what in examples]
    return info


def defect_warnings(path: str, info: dict[str, Any]) -> list[str]:
    parts = []
    if info.get("repaired_lines"):
        parts.append(f"repaired {info['repaired_lines']} line(s) with control characters")
    if info.get("skipped_control_lines"):
        parts.append(f"skipped {info['skipped_control_lines']} line(s) of control characters")
    if info.get("skipped_bad_lines"):
        parts.append(f"skipped {info['skipped_bad_lines']} unreadable line(s)")
    if not parts:
        return []
    first = f" (first: {info['defects'][0]})" if info.get("defects") else ""
    return [f"{path}: " + ", ".join(parts) + first]
