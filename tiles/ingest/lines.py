"""Parsing whole lines of numbers into an array, with repairs of damaged lines (the text and S3DIS readers').

:func:`parse_block` reads a block of whole lines with pandas' C parser.
Control characters inside a line (seen in the raw S3DIS release, e.g.
``185\\x00187``) are repaired when removing them, or reading them as a
separator, gives a valid line, and the line is skipped otherwise; blank lines
are skipped; every repair and skip is counted (:class:`BlockStats`).  A line
with the wrong number of fields or a non-number is an error
(:class:`LineError`) unless the policy is ``skip``; a NaN or infinite value is
always an error.
"""
from __future__ import annotations

import io
import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

_NUMBER = re.compile(rb"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")
_SEPARATORS = np.zeros(256, dtype=bool)
_SEPARATORS[[9, 10, 13, 32, 44]] = True
#: The control bytes (all below 32 but tab, newline and carriage return; and DEL).
CONTROL = np.zeros(256, dtype=bool)
CONTROL[[c for c in range(32) if c not in (9, 10, 13)] + [127]] = True


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


def tokens(line: bytes) -> list[bytes]:
    """The fields of a line: separated by whitespace or commas."""
    return line.replace(b",", b" ").split()


def _numbers(fields: list[bytes]) -> bool:
    return all(_NUMBER.match(t) for t in fields)


def all_floats(fields: list[bytes]) -> bool:
    """True when every token reads as a float (NaN and infinity included: they are points, and errors)."""
    try:
        for t in fields:
            float(t)
    except ValueError:
        return False
    return True


def repair_line(line: bytes, ncols: int) -> tuple[bytes | None, str]:
    """A line with control characters: the repaired line (or None to skip it) and what was done."""
    cleaned = bytes(b for b in line if not CONTROL[b])
    if not tokens(cleaned):
        return None, "control characters only"
    as_sep = bytes(32 if CONTROL[b] else b for b in line)
    for candidate, how in ((cleaned, "removed"), (as_sep, "read as a separator")):
        toks = tokens(candidate)
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
    if not CONTROL[a].any():
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
    sep = _SEPARATORS[a] | CONTROL[a]
    tok_start = ~sep & np.r_[True, sep[:-1]]
    ctok = np.r_[0, np.cumsum(tok_start)]
    ntok = ctok[ends] - ctok[starts]
    cctl = np.r_[0, np.cumsum(CONTROL[a])]
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
        toks = tokens(line)
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
