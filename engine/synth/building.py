"""The plan of a generated building: spaces, walls with openings, elements made of primitives.

A :class:`Building` is what :func:`engine.synth.plan.plan_building` returns
and what the scan turns into points.  Geometry is kept in the building's local
frame (metres, z up, the ground floor at z = 0) and :class:`Frame` maps it to
world coordinates (yaw about the local origin, then the offset); every world
quantity a user sees -- the ground-truth document, the points -- goes through
that one transform.

Parts: a space whose estimated point count exceeds ``part_points`` is cut into
pieces along its longer horizontal axis (:class:`PartSpec`); one dask task scans
one piece, so memory stays bounded whatever the building's size.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from engine.synth.geometry import Box, Poly, Rect, oriented_bounds
from tiles.classes import CLASS_CODES
from tiles.groundtruth import GTElement, GTSpace, make_doc


@dataclass(frozen=True)
class Frame:
    """Local-to-world transform: rotate by ``yaw`` (radians) about the local origin, then add ``offset``."""

    yaw: float = 0.0
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def xyz(self, local: np.ndarray) -> np.ndarray:
        """World coordinates of local points ``(n, 3)``."""
        local = np.asarray(local, float)
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        out = np.empty_like(local)
        out[..., 0] = c * local[..., 0] - s * local[..., 1] + self.offset[0]
        out[..., 1] = s * local[..., 0] + c * local[..., 1] + self.offset[1]
        out[..., 2] = local[..., 2] + self.offset[2]
        return out

    def xy(self, local: np.ndarray) -> np.ndarray:
        local = np.asarray(local, float)
        return self.xyz(np.c_[local, np.zeros(len(local))])[:, :2]

    def angle(self, yaw: float) -> float:
        """A local yaw as a world yaw, wrapped to (-pi, pi]."""
        a = math.remainder(yaw + self.yaw, 2 * math.pi)
        return math.pi if a == -math.pi else a


@dataclass
class Opening:
    """A door or window in a wall: ``s0..s1`` metres along the wall from ``p0``, ``z0..z1`` local z.

    Doors: ``leaf`` is ``"closed"``, ``"open"`` or ``"none"`` (a bare doorway),
    ``leaves`` 1 or 2, ``swing`` the side (+1 left of the wall, -1 right) the
    leaves are on, ``angle`` how far an open leaf is turned (radians).
    """

    id: int
    kind: str
    wall: int
    s0: float
    s1: float
    z0: float
    z1: float
    leaf: str = "none"
    leaves: int = 1
    swing: int = 1
    angle: float = 0.0
    elements: list[int] = field(default_factory=list)
    mullion: float = 0.0  # windows: the spacing of vertical bars (0: one in the middle of a pane over 1.4 m)
    sill_board: bool = True  # windows: a sill board under the pane, inside
    style: str = ""  # windows of a ``windows`` building: punched, ribbon, full or tall ("": classic)

    @property
    def width(self) -> float:
        return self.s1 - self.s0


@dataclass
class Wall:
    """A straight wall: centre line ``p0 -> p1`` (local xy), ``thickness``, ``z0..z1``.

    ``left`` / ``right`` are the spaces on either side (left = the side of the
    normal turned +90 degrees from the direction; -1 outside the building; both
    the same for a partial wall inside an open-plan space).
    """

    id: int
    floor: int
    p0: tuple[float, float]
    p1: tuple[float, float]
    thickness: float
    z0: float
    z1: float
    left: int
    right: int
    kind: str = "interior"  # exterior | interior | partial
    openings: list[Opening] = field(default_factory=list)
    ext0: float = 0.0  # how far the wall body reaches past p0 / p1 (into the walls it meets)
    ext1: float = 0.0
    material: str = "solid"  # or "glass": a glazed partition (hardness ``glass``)
    glazing: tuple[float, float] = (0.0, 0.0)  # glass from / to this height above the floor (glass walls)
    lined: tuple[int, ...] = ()  # spaces whose face of this wall is lined by tall furniture (``hidden_walls``)

    @property
    def length(self) -> float:
        return float(math.hypot(self.p1[0] - self.p0[0], self.p1[1] - self.p0[1]))

    @property
    def direction(self) -> np.ndarray:
        d = np.subtract(self.p1, self.p0)
        return d / np.hypot(*d)

    @property
    def normal(self) -> np.ndarray:
        d = self.direction
        return np.array([-d[1], d[0]])

    @property
    def yaw(self) -> float:
        d = self.direction
        return math.atan2(d[1], d[0])

    def side_of(self, space: int) -> int:
        """+1 if ``space`` is on the left, -1 on the right."""
        return 1 if self.left == space else -1

    def body(self) -> np.ndarray:
        """The corners ``(4, 2)`` of the wall's solid footprint (including the reach into joints)."""
        d, n = self.direction, self.normal
        a = np.asarray(self.p0) - d * self.ext0
        b = np.asarray(self.p1) + d * self.ext1
        h = n * self.thickness / 2
        return np.array([a - h, b - h, b + h, a + h])


@dataclass
class Element:
    """One ground-truth element instance made of primitives (what the scan samples).

    ``center`` / ``size`` / ``yaw`` is its box in local coordinates, computed
    from the primitives by :meth:`fit_box` and grown by the space's noise bound
    so that it contains every scanned point of the instance.
    """

    id: int
    cls: str
    space: int
    prims: list[Rect | Poly | Box]
    yaw: float = 0.0
    center: np.ndarray | None = None
    size: np.ndarray | None = None
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def class_code(self) -> int:
        return CLASS_CODES[self.cls]

    def fit_box(self, margin: float) -> None:
        if not self.prims:  # a volume without surfaces (flying points): its box was set when it was made
            self.size = np.asarray(self.size, float) + 2 * margin
            return
        corners = np.concatenate([p.corners() for p in self.prims])
        self.center, size = oriented_bounds(corners, self.yaw)
        self.size = size + 2 * margin


@dataclass
class Space:
    """A space (room, hallway, ...) of one floor.

    ``cells`` are the centre-line rectangles it was made of (in the space's own
    frame, turned by ``axis`` radians from the building's local frame: 0 but in
    a wing at an angle), ``footprint`` the clear floor polygon (local xy,
    counter-clockwise), ``z0``/``z1`` its floor and ceiling heights,
    ``scanners`` the scan positions; ``density``, ``noise`` (sigma, metres) and
    ``brightness`` vary per space.

    Hard scan conditions (:mod:`engine.synth.hard.hardness`): ``scanned`` False for a
    room never scanned (no points); ``registration`` ``(tx, ty, tz, angle, px,
    py)`` the rigid error of its scan (metres, radians about ``(px, py)``) and
    ``scan_jitter`` ``(k, 4)`` the residual error of each scan position
    (``tx, ty, tz, angle`` about the position), whose largest displacement is
    ``jitter_bound``; ``flying`` and ``ghosts`` the rates of flying points and of
    reflections in ``mirrors`` (window panes, :class:`Rect`) outside
    ``outline`` (the floor's outer polygon, local xy); ``stairs`` the stair of a
    stair tower (see :mod:`engine.synth.hard.elements`).
    """

    id: int
    name: str
    type: str
    floor: int
    cells: list[tuple[float, float, float, float]]
    z0: float
    z1: float
    footprint: np.ndarray | None = None
    density: float = 1.0
    noise: float = 0.004
    noise_clip: float = 3.0  # the noise is clipped at this many sigmas (5: real scanners' tails, 3: the classic)
    brightness: float = 1.0
    voxel: float = 0.0  # the scan keeps one point per cell of a world grid this wide (m); 0: every point
    colours: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    scanners: np.ndarray | None = None
    elements: list[Element] = field(default_factory=list)
    occluders: list[Box] = field(default_factory=list)  # occlude but are not sampled (walls of L-shapes)
    walls: list[int] = field(default_factory=list)
    doors: list[int] = field(default_factory=list)
    windows: list[int] = field(default_factory=list)
    axis: float = 0.0
    scanned: bool = True
    registration: tuple[float, ...] | None = None
    scan_jitter: np.ndarray | None = None
    jitter_bound: float = 0.0
    flying: float = 0.0
    ghosts: float = 0.0
    mirrors: list[Rect] = field(default_factory=list)
    outline: np.ndarray | None = None
    stairs: dict[str, Any] | None = None

    @property
    def area(self) -> float:
        fp = self.footprint
        x, y = fp[:, 0], fp[:, 1]
        return float(abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) / 2)

    @property
    def noise_bound(self) -> float:
        """The largest displacement of a point from its surface (noise is clipped at ``noise_clip`` sigmas)."""
        return self.noise_clip * self.noise

    def registered(self, local: np.ndarray) -> np.ndarray:
        """Local points ``(n, 3)`` moved by the space's registration error (unchanged without one)."""
        if self.registration is None:
            return np.asarray(local, float)
        tx, ty, tz, angle, px, py = self.registration
        p = np.array(local, float, copy=True)
        c, s = math.cos(angle), math.sin(angle)
        x, y = p[..., 0] - px, p[..., 1] - py
        p[..., 0] = c * x - s * y + px + tx
        p[..., 1] = s * x + c * y + py + ty
        p[..., 2] += tz
        return p

    @property
    def registration_yaw(self) -> float:
        return 0.0 if self.registration is None else float(self.registration[3])


@dataclass(frozen=True)
class PartSpec:
    """One scan task: the ``piece``-th of ``pieces`` slabs of space ``space`` along ``axis``."""

    part_id: int
    space: int
    piece: int
    pieces: int
    axis: int
    lo: float
    hi: float
    estimate: int


@dataclass
class FloorInfo:
    index: int
    z: float  # floor level
    ceiling_max: float  # highest ceiling of the floor (local z)
    slab: tuple[float, float]  # the slab above this floor (local z range), empty for the top floor


@dataclass
class Building:
    """A generated building: plan, geometry, scan parameters and the parts to scan."""

    seed: int
    frame: Frame
    density: float
    spaces: list[Space]
    walls: list[Wall]
    openings: list[Opening]
    floors: list[FloorInfo]
    parts: list[PartSpec] = field(default_factory=list)
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def elements(self) -> list[Element]:
        return [e for s in self.spaces for e in s.elements]

    @property
    def floor_area(self) -> float:
        return float(sum(s.area for s in self.spaces))

    def world_bounds(self) -> np.ndarray:
        """``[minx, miny, minz, maxx, maxy, maxz]`` of the building in world coordinates (walls included)."""
        pts = [np.c_[w.body(), np.full(4, w.z0)] for w in self.walls]
        pts += [np.c_[w.body(), np.full(4, w.z1)] for w in self.walls]
        world = self.frame.xyz(np.concatenate(pts))
        return np.r_[world.min(0), world.max(0)]

    def origin(self) -> list[float]:
        """A round world point at the building's lower corner: the offset of its scaled coordinates."""
        b = self.world_bounds()
        return [float(math.floor(v)) - 1.0 for v in b[:3]]

    # -- the ground-truth document -------------------------------------------------------
    def ground_truth(self, counts: dict[str, dict[int, int]] | None = None) -> dict[str, Any]:
        """The ``meta/ground_truth`` document (world coordinates, metres, yaw in radians).

        The fields of :mod:`tiles.groundtruth` (``spaces``: id, name, type,
        floor, footprint, z_range; ``elements``: id, class, class_code, space,
        center, size, yaw), plus:

        * per space: ``area`` (m^2 of clear floor), ``doors`` and ``windows``
          (opening ids), ``neighbours`` (spaces behind its doors), ``walls``
          (wall ids around it), ``scanners`` (scan positions ``[x, y, z]``),
          ``points`` (scanned points, when ``counts`` is given);
        * per element: ``points``; ``opening`` (doors, windows: the opening id),
          ``partial`` (a partial wall), ``engaged`` (a column against a wall),
          ``kind`` (clutter: monitor, bin, plant, light, toilet, ...);
        * ``walls``: ``{id, floor, kind (exterior | interior | partial),
          segment [[x, y], [x, y]] (centre line), thickness, z_range,
          spaces [left, right] (-1 outside), openings}`` -- the void between
          the faces is ``thickness`` wide, along the whole segment;
        * ``openings``: ``{id, kind (door | window), wall, spaces, center,
          width, height, yaw, elements}``, doors also ``leaf`` (open | closed |
          none), ``leaves`` (1 | 2) and ``leaf_space``;
        * ``floors``: ``{index, z (floor level), ceiling_max, slab [z0, z1]}``;
        * ``building``: the generation parameters, ``yaw_deg``, ``offset``, ``floor_area_m2``.

        Instances: one ``wall`` per edge of a space's clear footprint (a face,
        as S3DIS annotates walls per room; the segments of a curved wall are one
        instance); one ``door`` per side of a door opening; every clutter object
        is its own instance, so every generated point has ``gt_instance >= 0``
        except reflections (hardness ``artefacts``: ``gt_space`` and
        ``gt_instance`` -1, class clutter).  Boxes contain all of their
        instance's points (geometry grown by the space's noise bound, 3 sigma +
        1 mm, and by the residual registration error of its scan positions; a
        registered space's boxes move with its scan and keep the building's axes,
        each the box of those axes that encloses its turned self: S3DIS's boxes,
        and the foreign buildings', are in the building's frame, and a scan's
        registration error does not turn the walls that were built).
        ``counts`` is ``{"spaces": {id: n}, "elements": {id: n}}``.

        With hard scan conditions (:mod:`engine.synth.hard.hardness`), also: per
        space ``scanned`` (False: never scanned, no points), ``axis_deg`` (its
        own frame: a wing at an angle), ``registration`` (``{"offset": [dx, dy,
        dz], "yaw_deg", "pivot": [x, y]}`` world, the rigid error of its scan);
        per wall ``material`` (``solid`` | ``glass``) and ``lined`` (spaces whose
        face is hidden by tall furniture); ``building.hardness`` (the levels).
        """
        fr = self.frame
        hard = bool(self.params.get("hardness"))
        spaces, elements = [], []
        for s in self.spaces:
            fp = [[float(x), float(y)] for x, y in fr.xy(s.footprint)]
            spaces.append(GTSpace(s.id, s.name, s.type, s.floor, fp,
                                  [float(s.z0 + fr.offset[2]), float(s.z1 + fr.offset[2])]))
            turn = s.registration_yaw  # the scan's error turns the element's points, not the building's axes
            cos, sin = abs(math.cos(turn)), abs(math.sin(turn))
            for e in s.elements:
                c = fr.xyz(s.registered(e.center[None]))[0]
                sx, sy, sz = (float(v) for v in e.size)
                elements.append(GTElement(e.id, e.cls, e.class_code, s.id, [float(v) for v in c],
                                          [cos * sx + sin * sy, sin * sx + cos * sy, sz], float(fr.angle(e.yaw))))
        doc = make_doc(spaces, elements)
        for d, s in zip(doc["spaces"], self.spaces):
            self._space_doc(d, s, counts, hard)
        for d, e in zip(doc["elements"], self.elements):
            if e.info:
                d.update(e.info)
            if counts is not None:
                d["points"] = int(counts["elements"].get(e.id, 0))
        doc["walls"] = [self._wall_doc(w, hard) for w in self.walls]
        doc["openings"] = [self._opening_doc(o) for o in self.openings]
        doc["floors"] = [{"index": f.index, "z": f.z + fr.offset[2], "ceiling_max": f.ceiling_max + fr.offset[2],
                          "slab": [v + fr.offset[2] for v in f.slab]} for f in self.floors]
        doc["building"] = dict(self.params, yaw_deg=math.degrees(fr.yaw), offset=list(fr.offset),
                               floor_area_m2=round(self.floor_area, 3))
        return doc

    def _space_doc(self, d: dict[str, Any], s: Space, counts: dict[str, dict[int, int]] | None, hard: bool) -> None:
        """Add a space's own fields (area, openings, neighbours, walls, scanners, points, difficulties) to ``d``."""
        fr = self.frame
        d["area"] = round(s.area, 4)
        d["neighbours"] = sorted({o for oid in s.doors for o in self._door_spaces(oid) if o != s.id})
        d["doors"] = list(s.doors)
        d["windows"] = list(s.windows)
        d["walls"] = list(s.walls)
        d["scanners"] = [[float(v) for v in p] for p in fr.xyz(s.scanners)]
        if counts is not None:
            d["points"] = int(counts["spaces"].get(s.id, 0))
        if hard:
            d["scanned"] = bool(s.scanned)
            d["axis_deg"] = math.degrees(s.axis)
            if s.registration is not None:
                tx, ty, tz, angle, px, py = s.registration
                c, sn = math.cos(fr.yaw), math.sin(fr.yaw)
                d["registration"] = {"offset": [c * tx - sn * ty, sn * tx + c * ty, tz],
                                     "yaw_deg": math.degrees(angle),
                                     "pivot": [float(v) for v in fr.xy(np.array([[px, py]]))[0]]}

    def _door_spaces(self, opening_id: int) -> list[int]:
        o = self.openings[opening_id]
        w = self.walls[o.wall]
        return [s for s in (w.left, w.right) if s >= 0]

    def _wall_doc(self, w: Wall, hard: bool = False) -> dict[str, Any]:
        fr = self.frame
        seg = fr.xy(np.array([w.p0, w.p1]))
        d = {"id": w.id, "floor": w.floor, "kind": w.kind,
             "segment": [[float(v) for v in p] for p in seg], "thickness": float(w.thickness),
             "z_range": [float(w.z0 + fr.offset[2]), float(w.z1 + fr.offset[2])],
             "spaces": [int(w.left), int(w.right)], "openings": [o.id for o in w.openings]}
        if hard:
            d["material"] = w.material
            d["lined"] = [int(v) for v in w.lined]
        return d

    def _opening_doc(self, o: Opening) -> dict[str, Any]:
        fr = self.frame
        w = self.walls[o.wall]
        mid = np.asarray(w.p0) + w.direction * (o.s0 + o.s1) / 2
        c = fr.xyz(np.array([[mid[0], mid[1], (o.z0 + o.z1) / 2]]))[0]
        d = {"id": o.id, "kind": o.kind, "wall": o.wall, "spaces": [int(w.left), int(w.right)],
             "center": [float(v) for v in c], "width": float(o.width), "height": float(o.z1 - o.z0),
             "yaw": float(fr.angle(w.yaw)), "elements": list(o.elements)}
        if o.kind == "door":
            d.update(leaf=o.leaf, leaves=o.leaves,
                     leaf_space=int(w.left if o.swing > 0 else w.right) if o.leaf != "none" else None)
        return d
