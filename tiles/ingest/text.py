"""Plain text point clouds: one point per line, ``x y z`` or ``x y z r g b``, whitespace or comma separated.

Files ending in ``.txt``, ``.xyz``, ``.pts``, ``.csv`` or ``.asc``.  Lines before
the first point line that are not points (a column header such as
``//X Y Z R G B``, the point count line of a ``.pts`` file) are skipped and
counted.  Coordinates are stored on a 0.1 mm grid (``buildingparser.ingest.scale``)
around a round offset near the first point; colours are integers 0-65535
(0-255 for 8-bit colour, scaled to 16 bits on export).

Parts are byte ranges of the file, cut on line boundaries (a line belongs to the
part its first byte falls in), parsed by pandas' C parser.  Damaged lines are
handled by :func:`parse_block`: control characters inside a line (seen in the
raw S3DIS release, e.g. ``185\\x00187``) are repaired when removing them, or
reading them as a separator, gives a valid line, and the line is skipped
otherwise; blank lines are skipped; every repair and skip is counted and
reported.  A line with the wrong number of fields or a non-number is an error
naming the file and line unless ``buildingparser.ingest.bad-lines`` is ``skip``;
a NaN or infinite coordinate is always an error.
"""
from __future__ import annotations

import io
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import dask
import numpy as np

from tiles.errors import UserError
from tiles.ingest._common import (DEFAULT_SCALE, PartResult, Quantization, Reader, check_file, file_size,
                                  open_binary)
from tiles.schema import Dimension, coordinate_dimensions

EXTENSIONS = (".txt", ".xyz", ".pts", ".csv", ".asc")
SNIFF_BYTES = 1 << 16
_NUMBER = re.compile(rb"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")
_SEPARATORS = np.zeros(256, dtype=bool)
_SEPARATORS[[9, 10, 13, 32, 44]] = True
_CONTROL = np.zeros(256, dtype=bool)
_CONTROL[[c for c in range(32) if c not in (9, 10, 13)] + [127]] = True


def color_dimensions() -> list[Dimension]:
    return [Dimension(c, "uint16", "las", f"{c} colour", {"name": c}) for c in ("red", "green", "blue")]


def grid_scale() -> float:
    """The coordinate step of sources without their own (``buildingparser.ingest.scale``)."""
    return float(dask.config.get("buildingparser.ingest.scale", DEFAULT_SCALE))


def bad_line_policy() -> str:
    policy = str(dask.config.get("buildingparser.ingest.bad-lines", "error"))
    if policy not in ("error", "skip"):
        raise UserError(None, f"buildingparser.ingest.bad-lines must be 'error' or 'skip', not {policy!r}")
    return policy


# -- the parser -----------------------------------------------------------------------------

@dataclass
class BlockStats:
    """What parsing one block found, besides its points."""

    points: int = 0
    newlines: int = 0
    blank: int = 0
    repaired: int = 0
    skipped_control: int = 0
    skipped_bad: int = 0
    #: (byte position in the block, what) of the first few defects
    examples: list[tuple[int, str]] = field(default_factory=list)

    def note(self, pos: int, what: str) -> None:
        if len(self.examples) < 5:
            self.examples.append((pos, what))

    def to_json(self) -> dict[str, Any]:
        return {"points": self.points, "blank_lines": self.blank, "repaired_lines": self.repaired,
                "skipped_control_lines": self.skipped_control, "skipped_bad_lines": self.skipped_bad}


class LineError(Exception):
    """A bad line in a block: byte position in the block and the problem."""

    def __init__(self, pos: int, message: str):
        super().__init__(message)
        self.pos = pos
        self.message = message


def _tokens(line: bytes) -> list[bytes]:
    return line.replace(b",", b" ").split()


def _numbers(tokens: list[bytes]) -> bool:
    return all(_NUMBER.match(t) for t in tokens)


def _floats(tokens: list[bytes]) -> bool:
    """True when every token reads as a float (NaN and infinity included: they are points, and errors)."""
    try:
        for t in tokens:
            float(t)
    except ValueError:
        return False
    return True


def repair_line(line: bytes, ncols: int) -> tuple[bytes | None, str]:
    """A line with control characters: the repaired line (or None to skip it) and what was done."""
    cleaned = bytes(b for b in line if not _CONTROL[b])
    if not _tokens(cleaned):
        return None, "control characters only"
    as_sep = bytes(32 if _CONTROL[b] else b for b in line)
    for candidate, how in ((cleaned, "removed"), (as_sep, "read as a separator")):
        toks = _tokens(candidate)
        if len(toks) == ncols and _numbers(toks):
            return b" ".join(toks), f"control characters {how}"
    return None, f"control characters in an unreadable line {line[:60]!r}"


def parse_block(buf: bytes, ncols: int, sep: str, *, policy: str = "error") -> tuple[np.ndarray, BlockStats]:
    """Parse whole lines of numbers into a float64 ``(n, ncols)`` array; see the module doc for repairs.

    Raises :class:`LineError` for a line that cannot be read (unless ``policy`` is
    ``skip``) and for a non-finite value.
    """
    stats = BlockStats()
    a = np.frombuffer(buf, dtype=np.uint8)
    stats.newlines = int(np.count_nonzero(a == 10))
    if not len(a):
        return np.empty((0, ncols)), stats
    if not _CONTROL[a].any():
        import pandas as pd  # here, not at the top: importing pandas costs every ingest ~0.4 s otherwise

        try:
            vals = _fast(buf, ncols, sep)
        except (ValueError, pd.errors.ParserError):
            vals = None
        if vals is not None and np.isfinite(vals).all():
            stats.points = len(vals)
            return vals, stats
    vals = _careful(buf, a, ncols, stats, policy)
    stats.points = len(vals)
    return vals, stats


def _fast(buf: bytes, ncols: int, sep: str) -> np.ndarray | None:
    import pandas as pd

    df = pd.read_csv(io.BytesIO(buf), sep=sep, header=None, dtype=np.float64, engine="c",
                     skip_blank_lines=False, na_filter=True)
    if df.shape[1] != ncols:
        return None
    return df.to_numpy()


def _careful(buf: bytes, a: np.ndarray, ncols: int, stats: BlockStats, policy: str) -> np.ndarray:
    """Classify every line with whole-array operations; only damaged lines are handled one by one."""
    nl = np.flatnonzero(a == 10)
    starts = np.r_[0, nl + 1]
    ends = np.r_[nl, len(a)]
    keep_last = starts[-1] < len(a)
    if not keep_last:
        starts, ends = starts[:-1], ends[:-1]
    sep = _SEPARATORS[a] | _CONTROL[a]
    tok_start = ~sep & np.r_[True, sep[:-1]]
    ctok = np.r_[0, np.cumsum(tok_start)]
    ntok = ctok[ends] - ctok[starts]
    cctl = np.r_[0, np.cumsum(_CONTROL[a])]
    nctl = cctl[ends] - cctl[starts]
    good = (ntok == ncols) & (nctl == 0)
    blank = (ntok == 0) & (nctl == 0)
    stats.blank += int(blank.sum())
    fixed: dict[int, bytes] = {}
    for i in np.flatnonzero(~good & ~blank):
        line = bytes(buf[starts[i]:ends[i]])
        if nctl[i]:
            repaired, what = repair_line(line, ncols)
            if repaired is None:
                stats.skipped_control += 1
            else:
                stats.repaired += 1
                fixed[int(i)] = repaired
            stats.note(int(starts[i]), what)
        else:
            _bad(stats, policy, int(starts[i]), f"{int(ntok[i])} fields, expected {ncols}: {line[:60]!r}")
    idx = np.union1d(np.flatnonzero(good), np.fromiter(fixed, dtype=np.int64, count=len(fixed)))
    text = _join_lines(a, starts, ends, good, fixed)
    if not text:
        return np.empty((0, ncols))
    import pandas as pd

    try:
        vals = pd.read_csv(io.BytesIO(text.replace(b",", b" ")), sep=r"\s+", header=None, dtype=np.float64,
                           engine="c").to_numpy()
        line_pos = starts[idx]
    except ValueError:
        vals, line_pos = _by_line(buf, starts, ends, idx, fixed, ncols, stats, policy)
    if vals.shape[0] != len(line_pos) or vals.shape[1] != ncols:
        vals, line_pos = _by_line(buf, starts, ends, idx, fixed, ncols, stats, policy)
    bad = ~np.isfinite(vals).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise LineError(int(line_pos[i]), f"not a finite number (NaN or infinity) in {vals[i].tolist()}")
    return vals


def _join_lines(a: np.ndarray, starts: np.ndarray, ends: np.ndarray, good: np.ndarray,
                fixed: dict[int, bytes]) -> bytes:
    """The good lines (selected with a byte mask) with the repaired lines spliced in at their places."""
    lens = ends - starts + 1
    if len(lens) and ends[-1] == len(a):
        lens[-1] -= 1  # the last line has no newline
    mask = np.repeat(good, lens)
    out, prev = [], 0
    for i in sorted(fixed):
        cut = int(starts[i])
        out.append(a[prev:cut][mask[prev:cut]].tobytes())
        if out[-1] and not out[-1].endswith(b"\n"):
            out.append(b"\n")
        out.append(fixed[i] + b"\n")
        prev = cut
    out.append(a[prev:][mask[prev:]].tobytes())
    return b"".join(out)


def _by_line(buf, starts, ends, idx, fixed, ncols, stats, policy):
    """Slow path for the rare blocks with non-numeric fields: find them line by line."""
    vals, pos = [], []
    for i in idx.tolist():
        line = fixed[i] if i in fixed else bytes(buf[starts[i]:ends[i]])
        toks = _tokens(line)
        try:
            row = [float(t) for t in toks]
        except ValueError:
            _bad(stats, policy, int(starts[i]), f"not a number in {line[:60]!r}")
            continue
        vals.append(row)
        pos.append(starts[i])
    return np.array(vals, dtype=np.float64).reshape(-1, ncols), np.array(pos, dtype=np.int64)


def _bad(stats: BlockStats, policy: str, pos: int, what: str) -> None:
    if policy != "skip":
        raise LineError(pos, what + " (set buildingparser.ingest.bad-lines: skip to skip such lines)")
    stats.skipped_bad += 1
    stats.note(pos, what)


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
        toks = _tokens(bytes(c for c in line if not _CONTROL[c]))
        if toks and len(toks) in allowed and _floats(toks):
            vals = np.array([float(t) for t in toks])
            if not np.isfinite(vals).all():
                raise UserError(path, f"line {k + 1}: not a finite number (NaN or infinity) in {line[:60]!r}")
            sep = "," if b"," in line else ("\t" if b"\t" in line and b" " not in line else
                                            (" " if re.fullmatch(rb"\S+( \S+)*\r?", line) else r"\s+"))
            n_lines = max(1, len(lines) - k)
            per_line = (len(head) - pos) / n_lines
            return Sniff(pos, len(toks), sep, header, vals[:3], per_line)
        if toks and _floats(toks) and len(toks) not in allowed and len(toks) > 1:
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
