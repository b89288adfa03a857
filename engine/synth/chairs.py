"""Chairs of the ``furniture`` style family: shapes and sizes the classic catalogue does not have.

The classic chair (:func:`engine.synth.pieces.chair`) is a 0.46 m seat on four legs or on a post with a cross of
two 0.56 m bars.  A ``furniture`` building draws each chair's shape from its own stream instead (the room's other
draws stay the classic building's): an office chair on a five-star base 0.56-0.72 m across with casters, a
cantilever chair on floor runners, an upholstered armchair standing on the floor, a stool (low or bar height,
legs splayed wider than its seat, no back), or a wide chair on four legs (0.5-0.6 m seat).  The five-star base's
arms are boxes turned about z: a :data:`engine.synth.pieces.Part` with an eighth value, its turn in radians.
"""
from __future__ import annotations

import math

import numpy as np

from engine.synth import colours as C
from engine.synth.pieces import Part

#: The shapes, drawn with these weights.
SHAPES = ("five-star", "cantilever", "armchair", "stool", "wide")
WEIGHTS = (0.35, 0.15, 0.15, 0.15, 0.2)


def chair_stream(furniture: int, space: int, k: int) -> np.random.Generator:
    """The stream of the ``k``-th chair placed in a room of a ``furniture`` building (``furniture``: the
    building's family seed)."""
    return np.random.default_rng([int(furniture), int(space), int(k)])


def chair_shape(r: np.random.Generator) -> str:
    """The shape of a family chair: the first draw of its stream."""
    return SHAPES[int(r.choice(len(SHAPES), p=WEIGHTS))]


def family_chair(r: np.random.Generator, rgb: tuple) -> tuple[list[Part], str]:
    """One chair of the family (local frame: origin on the floor under its middle, back towards +y) and its
    shape's name."""
    shape = chair_shape(r)
    return {"five-star": _five_star, "cantilever": _cantilever, "armchair": _armchair, "stool": _stool,
            "wide": _wide}[shape](r, rgb), shape


def _seat_and_back(r: np.random.Generator, rgb: tuple, seat_z: float, width: float, depth: float) -> list[Part]:
    back_h = r.uniform(0.35, 0.6)
    return [(0, 0, seat_z, width, depth, 0.07, rgb),
            (0, depth / 2 - 0.03, seat_z + 0.035 + back_h / 2, width * r.uniform(0.85, 1.0), 0.06, back_h, rgb)]


def _five_star(r: np.random.Generator, rgb: tuple) -> list[Part]:
    seat_z = r.uniform(0.42, 0.52)
    reach = r.uniform(0.3, 0.38)  # the arms' length: the base 0.56-0.72 m across
    parts = _seat_and_back(r, rgb, seat_z, r.uniform(0.46, 0.54), r.uniform(0.45, 0.52))
    parts.append((0, 0, (0.1 + seat_z - 0.035) / 2, 0.05, 0.05, seat_z - 0.035 - 0.1, C.METAL))  # the gas post
    turn = r.uniform(0, 2 * math.pi / 5)
    for k in range(5):
        a = turn + 2 * math.pi * k / 5
        c, s = math.cos(a), math.sin(a)
        parts.append((c * reach / 2, s * reach / 2, 0.075, reach, 0.05, 0.04, C.METAL, a))  # an arm
        parts.append((c * (reach - 0.025), s * (reach - 0.025), 0.0275, 0.05, 0.05, 0.055, C.METAL))  # its caster
    if r.random() < 0.5:
        for sx in (-1, 1):
            parts.append((sx * 0.26, -0.02, seat_z + 0.22, 0.05, 0.3, 0.03, C.METAL))
            parts.append((sx * 0.26, 0.05, seat_z + 0.1, 0.03, 0.03, 0.2, C.METAL))
    return parts


def _cantilever(r: np.random.Generator, rgb: tuple) -> list[Part]:
    seat_z, width, depth = r.uniform(0.43, 0.48), r.uniform(0.44, 0.5), r.uniform(0.45, 0.55)
    run = depth + r.uniform(0.05, 0.15)  # the runners reach past the seat's front
    parts = _seat_and_back(r, rgb, seat_z, width, depth)
    for sx in (-1, 1):
        x = sx * (width / 2 - 0.01)
        parts.append((x, 0.02 - (run - depth) / 2, 0.01, 0.025, run, 0.02, C.METAL))  # a runner on the floor
        parts.append((x, -depth / 2 + 0.03, (0.02 + seat_z) / 2, 0.025, 0.025, seat_z - 0.02, C.METAL))  # its upright
    return parts


def _armchair(r: np.random.Generator, rgb: tuple) -> list[Part]:
    width, depth, top = r.uniform(0.65, 0.85), r.uniform(0.7, 0.85), r.uniform(0.75, 0.95)
    arm, seat_z = r.uniform(0.1, 0.18), r.uniform(0.4, 0.45)
    return [(0, -0.05, seat_z / 2, width - 2 * arm, depth - 0.1, seat_z, rgb),  # the base, on the floor
            (0, depth / 2 - 0.075, top / 2, width, 0.15, top, rgb),  # the back
            (-(width - arm) / 2, 0, seat_z / 2 + 0.1, arm, depth, seat_z + 0.2, rgb),  # the arms, to the floor
            ((width - arm) / 2, 0, seat_z / 2 + 0.1, arm, depth, seat_z + 0.2, rgb)]


def _stool(r: np.random.Generator, rgb: tuple) -> list[Part]:
    seat_z, seat = (r.uniform(0.44, 0.5) if r.random() < 0.5 else r.uniform(0.65, 0.8)), r.uniform(0.32, 0.4)
    foot = seat / 2 + r.uniform(0.03, 0.1)  # splayed: the feet stand wider than the seat
    parts: list[Part] = [(0, 0, seat_z, seat, seat, 0.05, rgb)]
    for sx in (-1, 1):
        for sy in (-1, 1):
            parts.append((sx * (foot - 0.06), sy * (foot - 0.06), (seat_z - 0.025) / 2, 0.03, 0.03, seat_z - 0.025, C.METAL))
            parts.append((sx * (foot - 0.03), sy * (foot - 0.03), 0.015, 0.06, 0.06, 0.03, C.METAL))
    return parts


def _wide(r: np.random.Generator, rgb: tuple) -> list[Part]:
    seat_z, width, depth = r.uniform(0.43, 0.48), r.uniform(0.5, 0.6), r.uniform(0.5, 0.58)
    parts = _seat_and_back(r, rgb, seat_z, width, depth)
    legs = r.choice([C.METAL, rgb])
    for sx in (-1, 1):
        for sy in (-1, 1):
            parts.append((sx * (width / 2 - 0.03), sy * (depth / 2 - 0.03), (seat_z - 0.035) / 2, 0.035, 0.035,
                          seat_z - 0.035, tuple(legs)))
    return parts
