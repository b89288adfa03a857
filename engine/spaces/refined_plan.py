"""The building's cells and edges with the refinements' appended, and the spaces renumbered.

Building faces beside a refined space are cut where the new space beyond
changes (:func:`face_side_space`); spaces rejoined after the refinement
(:mod:`engine.spaces.rejoin`) are regrouped (:meth:`RefinedPlan.regroup`).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from engine.spaces.alignment import Frame
from engine.spaces.merging import Edge
from engine.spaces.refine import Refinement
from engine.spaces.slicing import Box, FoundDivider


@dataclass
class RefinedPlan:
    """The building's cells and edges with the refinements' appended, and the spaces renumbered.

    A refined space's own cells keep their ids but get no space (-1); its new
    cells follow the building's (``firsts[k]``: the first of refinement ``k``)
    and their spaces replace it, numbered in its place.  ``sides[e]`` is the
    space on each side of edge ``e``: a building edge next to a refined space
    gets the new space found on its side of the face; ``edge_yaw[e]`` the frame
    of a refinement's edge (None: the building's).
    """

    cells: list[Box]
    edges: list[Edge]
    labels: np.ndarray
    owner: np.ndarray
    refinements: list[Refinement]
    firsts: list[list[int]]
    cell_yaw: list[float | None]
    edge_yaw: list[float | None]
    sides: np.ndarray
    sub_of: dict[int, tuple[int, float]]
    clip: dict[int, list[int]]
    dividers: list[FoundDivider]
    n_spaces: int
    #: The pieces of the building faces between two refined spaces that were cut where the new space on a
    #: side changes (indices into ``edges``): each still carries the divider found on the whole face and is
    #: tested again on its own stretch.  Beside a space that was not refined, a piece keeps the whole face's
    #: divider (a piece's own stretch misled the test there: an outer wall beside unscanned ground that a
    #: refined piece had stretched over, h400-2storeys-yaw-20 0.983 -> 0.943).
    pieces: list[int] = field(default_factory=list)
    #: After :meth:`regroup`: new space -> the spaces (before regrouping) it joins, when more than one,
    #: and each cell's space before regrouping.
    joined: dict[int, list[int]] = field(default_factory=dict)
    before: np.ndarray | None = None
    sub_before: dict[int, tuple[int, float]] = field(default_factory=dict)
    #: The building frame's yaw (None: not known; every edge then counts as in its sides' frames).
    frame_yaw: float | None = None

    def frames_agree(self) -> np.ndarray:
        """Per edge: whether each side's space was parsed in the frame of the edge (a face of the building's
        frame between spaces of the building's frame, or a refinement's face between spaces of its frame)."""
        if self.frame_yaw is None:
            return np.ones(len(self.edges), dtype=bool)

        def space_yaw(s: int) -> float | None:
            if s < 0 or s not in self.sub_of:
                return None
            y = self.sub_of[s][1]
            return None if y == self.frame_yaw else y

        return np.array([all(int(s) < 0 or space_yaw(int(s)) == y for s in row)
                         for row, y in zip(self.sides.tolist(), self.edge_yaw)], dtype=bool).reshape(-1)

    def regroup(self, group: np.ndarray) -> None:
        """Join spaces: ``group[s]`` is the space ``s`` joins (:func:`engine.spaces.rejoin.rejoin_pieces`); renumbered."""
        group = np.asarray(group, dtype=np.int64)
        if np.array_equal(group, np.arange(self.n_spaces)):
            return
        ids = np.unique(group)
        new_of = np.searchsorted(ids, group)  # old space -> new space
        remap = np.append(new_of, -1)  # -1 stays -1
        self.before = self.labels.copy()
        self.sub_before = dict(self.sub_of)
        self.labels = remap[self.labels]
        self.sides = remap[self.sides]
        members: dict[int, list[int]] = {}
        for old, new in enumerate(new_of.tolist()):
            members.setdefault(new, []).append(old)
        self.joined = {new: olds for new, olds in members.items() if len(olds) > 1}
        self.sub_of = {int(new_of[old]): v for old, v in self.sub_before.items()
                       if int(new_of[old]) not in self.joined}
        self.n_spaces = len(ids)

    @classmethod
    def build(cls, cells: list[Box], edges: list[Edge], labels: np.ndarray, refs: list[Refinement],
              frame: Frame | None = None, bin_width: float = 0.01) -> RefinedPlan:
        """The plan of a parse's ``cells``, ``edges`` and spaces (``labels``) with the refinements ``refs`` that
        split their space (into two spaces or more; the others are left out)."""
        num = _Numbering.of(labels, refs)
        old = np.asarray(labels, dtype=np.int64)
        owner = np.full(len(cells) + 1, -1, dtype=np.int64)
        for k, r in enumerate(num.kept):
            owner[1:][old == r.space] = k
        all_edges, rows, pieces = _building_edges(edges, old, num, frame, bin_width)
        out = cls(list(cells), all_edges, np.zeros(0, np.int64), owner, num.kept, [], [None] * len(cells),
                  [None] * len(all_edges), np.array(rows, dtype=np.int64).reshape(-1, 2), {}, {}, [], num.n_spaces,
                  pieces=pieces, frame_yaw=None if frame is None else frame.yaw)
        lab = [num.new_id[old]]  # old -1 -> new_id[-1] = -1
        for k, r in enumerate(num.kept):
            lab += out._append(k, r, num.base[r.space], frame)
            out.clip[k] = np.flatnonzero(old == r.space).tolist()
        out.labels = np.concatenate(lab) if lab else np.zeros(0, np.int64)
        return out

    def _append(self, k: int, r: Refinement, at: int, frame: Frame | None) -> list[np.ndarray]:
        """Append the cells, edges and dividers of refinement ``k``'s parts, its new spaces numbered from ``at``;
        the new spaces of its cells, per part."""
        self.firsts.append([])
        lab = []
        for pt in r.parts:
            first = len(self.cells)
            self.firsts[-1].append(first)
            self.cells += pt.cells
            self.cell_yaw += [None if frame is not None and pt.yaw == frame.yaw else pt.yaw] * len(pt.cells)
            sl = np.asarray(pt.labels, dtype=np.int64)
            sub_sides = np.where(sl >= 0, sl + at, -1)
            lab.append(sub_sides)
            rows = []
            for e in pt.edges:
                self.edges.append(dataclasses.replace(e, a=e.a + first, b=e.b + first))
                rows.append([sub_sides[e.a], sub_sides[e.b]])
            self.edge_yaw += [None if frame is not None and pt.yaw == frame.yaw else pt.yaw] * len(pt.edges)
            self.sides = np.vstack([self.sides, np.array(rows, dtype=np.int64).reshape(-1, 2)])
            for j in range(pt.n_spaces):
                self.sub_of[at + j] = (k, pt.yaw)
            at += pt.n_spaces
            self.dividers += pt.dividers
        return lab


@dataclass
class _Numbering:
    """The new number of every space: a refined space's new spaces in its place, from ``base[space]``."""

    kept: list[Refinement]  # the refinements that split their space
    ref_of: dict[int, int]  # refined space -> its refinement's index in ``kept``
    new_id: np.ndarray  # old space -> new (-1: refined or none; ``new_id[-1]`` is -1)
    base: dict[int, int]
    n_spaces: int

    @classmethod
    def of(cls, labels: np.ndarray, refs: list[Refinement]) -> _Numbering:
        kept = [r for r in refs if r.n_spaces >= 2]
        ref_of = {r.space: k for k, r in enumerate(kept)}
        n_old = int(labels.max()) + 1 if len(labels) and labels.max() >= 0 else 0
        new_id = np.full(n_old + 1, -1, dtype=np.int64)  # old space -> new (-1: refined or none)
        base: dict[int, int] = {}
        nxt = 0
        for sp in range(n_old):
            if sp in ref_of:
                base[sp] = nxt
                nxt += kept[ref_of[sp]].n_spaces
            else:
                new_id[sp] = nxt
                nxt += 1
        return cls(kept, ref_of, new_id, base, nxt)


def _building_edges(edges: list[Edge], old: np.ndarray, num: _Numbering, frame: Frame | None, bin_width: float
                    ) -> tuple[list[Edge], list[list[int]], list[int]]:
    """The building's edges, the space on each side of each, and the pieces of faces between two refined spaces.

    The space on a refined side is the new space at the face.  A face beside a refined space is sampled every
    face-step bins along it and cut where the new space on either side changes: one long building face may
    border several of the refinement's spaces (a hallway's end and a room), and each piece must connect the
    right pair.
    """
    kept, ref_of, new_id, base = num.kept, num.ref_of, num.new_id, num.base
    origin = frame.origin if frame is not None else (0.0, 0.0, 0.0)

    def side(e: Edge, j: int, lo: int, at: float) -> int:
        step = -2 if j == 0 else 2  # a lies below the face, b above
        pt = [e.position + step, at] if e.axis == 0 else [at, e.position + step]
        world = frame.to_world(np.asarray(pt, dtype=np.float64) * bin_width)
        got = face_side_space(kept[ref_of[lo]], world, origin, bin_width)
        return base[lo] + got if got >= 0 else -1

    face_step = max(1, int(round(0.25 / bin_width)))
    all_edges, rows, pieces = [], [], []
    for e in edges:
        la, lb = int(old[e.a]), int(old[e.b])
        if (la == lb and la in ref_of) or (la not in ref_of and lb not in ref_of):
            # inside a refined space (its refinement has its own faces), or away from every refinement
            inside = la == lb and la in ref_of
            all_edges.append(e)
            rows.append([-1 if inside or la < 0 else new_id[la], -1 if inside or lb < 0 else new_id[lb]])
            continue
        o0, o1 = e.overlap
        marks = np.unique(np.r_[np.arange(o0, o1, face_step), o1 - 1]).astype(np.float64) + 0.5
        pairs = [tuple(-1 if lo < 0 else (new_id[lo] if lo not in ref_of else side(e, j, lo, t))
                       for j, lo in enumerate((la, lb))) for t in marks]
        start, first = o0, len(all_edges)
        for k in range(1, len(marks) + 1):
            if k == len(marks) or pairs[k] != pairs[k - 1]:
                stop = o1 if k == len(marks) else int(0.5 * (marks[k - 1] + marks[k]))
                if stop > start:
                    all_edges.append(dataclasses.replace(e, overlap=(start, stop)))
                    rows.append(list(pairs[k - 1]))
                start = stop
        if len(all_edges) - first > 1 and la in ref_of and lb in ref_of:
            pieces += range(first, len(all_edges))
    return all_edges, rows, pieces


def face_side_space(refinement: Refinement, point_world: np.ndarray, origin, bin_width: float) -> int:
    """The new space (numbered within the refinement) at a world point: the cell holding it in its part,
    else the nearest cell with a space of any part."""
    best, best_d, base = -1, np.inf, 0
    pw = np.asarray(point_world, dtype=np.float64)[None, :2]
    want = int(refinement.part_of(pw - np.asarray(origin[:2]))[0]) if refinement.regions is not None else 0
    for j, part in enumerate(refinement.parts):
        a = Frame(part.yaw, tuple(origin)).to_aligned(pw)[0] / bin_width
        rows = np.array([[c.u0, c.u1, c.v0, c.v1] for c in part.cells], dtype=np.float64).reshape(-1, 4)
        lab = np.asarray(part.labels)
        ok = lab >= 0
        if ok.any():
            du = np.maximum(np.maximum(rows[:, 0] - a[0], a[0] - rows[:, 1]), 0.0)
            dv = np.maximum(np.maximum(rows[:, 2] - a[1], a[1] - rows[:, 3]), 0.0)
            d = np.where(ok, np.hypot(du, dv), np.inf) + (0.0 if j == want else 1e6)
            i = int(np.argmin(d))
            if d[i] < best_d:
                best, best_d = base + int(lab[i]), float(d[i])
        base += part.n_spaces
    return best
