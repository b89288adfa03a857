"""The difficulties of real indoor scans that a generated building can be given (``--hard``).

A clean generated building is easy: one Manhattan frame, every room scanned
from inside, walls 0.1-0.35 m thick with two crisp faces, modest clutter.  Real
scans are hard in known ways; each way is one *difficulty* here, switched on
alone or together, with a *level* (0 off, 1 the documented hard setting, up
to 2 harsher: probabilities and magnitudes scale with it).

=================  =====================================================================================
name               what it adds (level 1), and where
=================  =====================================================================================
``registration``   imperfect registration: every space's scan is moved rigidly (translation ~N(0, 2 cm)
                   per axis, clipped at 5 cm; rotation up to 0.4 deg about its centre) and every scan
                   position within it once more (up to 1.2 cm, 0.08 deg): doubled wall faces where the
                   coverage of two scan positions meets, and the two faces of a shared wall offset
                   (:mod:`engine.synth.hard.scan`)
``glass``          glass partitions: a quarter of the room-hallway and room-room walls become glazed
                   partitions 0.08-0.12 m thick (sparse glass, 6 % of the density; mullions, rails and
                   an optional solid base or transom at normal density) with glass doors
                   (:mod:`engine.synth.hard.plan`, :mod:`engine.synth.faces`)
``unscanned``      rooms never scanned: one closed storage-like room per floor (two on big floors)
                   gets no scan position and no points; its walls are seen from outside only and its
                   doors are closed
``hidden_walls``   walls hidden by tall furniture: a third of the room-room walls (and some room-hallway
                   walls) lined over 60-95 % of their length by cabinets 2.0-2.4 m tall or up to the
                   ceiling, on one or both faces
``wing``           a wing at 15-40 deg to the main block (its own rooms and hallway, joined to the main
                   hallway through a link with diagonal walls): two Manhattan frames in one building
``oblique``        diagonal and curved walls: a chamfered building corner, a rounded corner (arc of
                   10-14 segments), and per floor one slanted or curved wall between two rooms
``bottlenecks``    hallways with bottlenecks (free-standing columns, pairs of piers facing each other,
                   sometimes with a soffit across: a portal; runs of tall lockers) and hallway ceilings
                   0.3-0.8 m higher than the rooms beside them
``open_plan``      large open spaces (a run of 3-6 rooms, up to 30 m, merged) with grids of free-standing
                   columns, and open-plan offices whose desks stand in cubicles of low partitions
                   (1.1-1.7 m) that do not divide the space
``walls``          very thin (drywall, 0.06-0.09 m) and very thick (structural, 0.35-0.7 m) walls
``clutter``        heavy clutter: piles of stacked boxes (1-2.2 m) in most rooms, against walls and free
``stairs``         stairs between floors: a stair tower at one end of the main hallway on every floor, a
                   U-shaped stair (two flights, a half landing) rising to the next floor through the slab
``artefacts``      sensor artefacts: flying points behind the edges of objects (mixed pixels: 30 % of
                   the points within 2.5 cm of an edge), and reflections seen through windows: ghost
                   points mirrored outside the building (4 % of the room's points tried per pane)
=================  =====================================================================================

Ground truth stays exact: every planned element keeps one instance whose box
contains all of its points (registration moves the boxes with the points, and
they keep the building's axes, enclosing the turned box; the per-scan-position
residual is added to the box margin).  Two kinds of points
are not surfaces of the plan, and their labels are a decision:

* **flying points** lie in the space they were scanned from (inside its footprint
  and height): ``gt_space`` = that space, ``gt_class`` = clutter, one clutter
  instance per space (``kind: "flying"``) whose box is the space's volume;
* **reflections** lie outside the building: ``gt_space = -1``, ``gt_class`` =
  clutter, ``gt_instance = -1`` (no object): the ARI of space parsing leaves
  them out (there is no space to compare with) and the S3DIS layout, which has
  no "outside", does not write them.

Randomness: every difficulty draws from its own stream
(``rng_for(seed, S_HARD, difficulty, ...)``), after the clean generator's own
draws, so switching a difficulty on changes only what it is about and a
building with no difficulty is exactly the clean one.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from tiles.errors import UserError

#: The difficulties, in the order of the table above.
NAMES = ("registration", "glass", "unscanned", "hidden_walls", "wing", "oblique", "bottlenecks", "open_plan",
         "walls", "clutter", "stairs", "artefacts")
#: Highest level accepted.
MAX_LEVEL = 2.0
#: Stream keys of the difficulties (second element of the spawn key after S_HARD).
KEYS = {name: k for k, name in enumerate(NAMES)}
#: First element of the spawn key of every hard stream (the clean streams use 0-3).
S_HARD = 7


def hard_rng(seed: int, name: str, *key: int) -> np.random.Generator:
    """The random stream of one difficulty for one object, independent of the clean generator's streams."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(S_HARD, KEYS[name],
                                                                               *(int(k) for k in key))))


@dataclass(frozen=True)
class Hardness:
    """The level of every difficulty: 0 off, 1 the documented hard setting, up to 2 harsher.

    Build one with :meth:`parse` from ``"all"``, ``"none"``, ``"glass,wing"``, a
    list of names, a mapping ``{name: level}`` or another :class:`Hardness`.
    """

    registration: float = 0.0
    glass: float = 0.0
    unscanned: float = 0.0
    hidden_walls: float = 0.0
    wing: float = 0.0
    oblique: float = 0.0
    bottlenecks: float = 0.0
    open_plan: float = 0.0
    walls: float = 0.0
    clutter: float = 0.0
    stairs: float = 0.0
    artefacts: float = 0.0

    def __post_init__(self) -> None:
        for name in NAMES:
            v = float(getattr(self, name))
            if not 0.0 <= v <= MAX_LEVEL:
                raise UserError(None, f"hardness level of {name} must be between 0 and {MAX_LEVEL:g}, not {v:g}")
            object.__setattr__(self, name, v)

    def __bool__(self) -> bool:
        return any(getattr(self, n) > 0 for n in NAMES)

    def level(self, name: str) -> float:
        return float(getattr(self, name))

    def on(self, name: str) -> bool:
        return self.level(name) > 0

    @property
    def geometric(self) -> bool:
        """Whether the floor plan has non-rectangular spaces (planned with general polygons)."""
        return self.on("wing") or self.on("oblique") or self.on("stairs")

    def to_dict(self) -> dict[str, float]:
        """The difficulties switched on and their levels."""
        return {n: getattr(self, n) for n in NAMES if getattr(self, n) > 0}

    @classmethod
    def all(cls, level: float = 1.0) -> Hardness:
        return cls(**{n: level for n in NAMES})

    @classmethod
    def parse(cls, spec: Hardness | str | Iterable[str] | Mapping[str, float] | None) -> Hardness:
        """A :class:`Hardness` from any of the accepted forms (one-line :class:`UserError` on a mistake).

        ``None``, ``""``, ``"none"``: nothing; ``"all"``: everything at level 1;
        ``"glass,wing"`` or ``["glass", "wing"]``: those at level 1;
        ``"glass=0.5,wing"``: with levels; ``{"glass": 0.5}``: the same.
        """
        if spec is None or isinstance(spec, cls):
            return spec or cls()
        if isinstance(spec, Mapping):
            items = [(str(k), float(v)) for k, v in spec.items()]
        else:
            if isinstance(spec, str):
                words = [w.strip() for w in spec.split(",") if w.strip()]
            else:
                words = [str(w).strip() for w in spec]
            items = []
            for w in words:
                name, _, value = w.partition("=")
                try:
                    items.append((name.strip(), float(value) if value else 1.0))
                except ValueError:
                    raise UserError(None, f"hardness level must be a number: {w!r}") from None
        levels: dict[str, float] = {}
        for name, v in items:
            key = name.replace("-", "_").lower()
            if key == "none":
                continue
            if key == "all":
                levels.update({n: v for n in NAMES})
                continue
            if key not in NAMES:
                raise UserError(None, f"unknown difficulty {name!r}: choose from all, {', '.join(NAMES)}")
            levels[key] = v
        return cls(**levels)

    def replace(self, **levels: float) -> Hardness:
        return dataclasses.replace(self, **levels)


@dataclass(frozen=True)
class HardContext:
    """What the planners of one building need to know about its difficulties: the levels and the seed."""

    hardness: Hardness
    seed: int

    def on(self, name: str) -> bool:
        return self.hardness.on(name)

    def level(self, name: str) -> float:
        return self.hardness.level(name)

    def rng(self, name: str, *key: int) -> np.random.Generator:
        return hard_rng(self.seed, name, *key)
