"""The spaces of a floor: a room type for each draft, its ceiling height, a WC on every big floor."""
from __future__ import annotations

import numpy as np

from engine.synth.building import Space
from engine.synth.layout import CIRCULATION, Draft


def room_type(rng: np.random.Generator, d: Draft) -> str:
    """The S3DIS room type of a draft: circulation keeps its type, rooms by size and shape."""
    if d.type in ("hallway", "lobby", "openspace", "stairs"):
        return d.type
    area, width = d.area, d.width
    if d.type == "room_small":
        return str(rng.choice(["storage", "WC", "office"], p=[0.4, 0.3, 0.3]))
    if d.type == "room_l":
        return "conferenceRoom" if rng.random() < 0.3 else "office"
    if area < 11 or width < 2.9:
        return str(rng.choice(["storage", "WC", "office"], p=[0.4, 0.3, 0.3]))
    if area > 28 and rng.random() < 0.4:
        return "conferenceRoom"
    r = rng.random()
    return "storage" if r < 0.06 else "WC" if r < 0.12 else "office"


def new_space(d: Draft, sid: int, floor: int, z: float, base_h: float, rng: np.random.Generator,
               counters: dict[str, int]) -> Space:
    """A space of draft ``d`` with its type, name (``office_3``) and ceiling height (hallways lower, lobbies higher)."""
    t = room_type(rng, d)
    counters[t] += 1
    h = base_h
    if t == "hallway":
        h = max(2.6, base_h - rng.uniform(0.0, 0.3))
    elif t == "lobby":
        h = min(4.0, base_h + rng.uniform(0.3, 0.9))
    elif t in ("conferenceRoom", "openspace"):
        h = min(4.0, base_h + rng.uniform(0.0, 0.5))
    elif rng.random() < 0.2:
        h = base_h - rng.uniform(0.0, 0.1)
    return Space(sid, f"{t}_{counters[t]}", t, floor, list(d.cells), z0=z, z1=round(z + h, 3), axis=d.axis)


def ensure_wc(floor_spaces: list[Space], counters: dict[str, int]) -> None:
    """Every floor with five rooms or more has a WC: the smallest office becomes one."""
    rooms = [s for s in floor_spaces if s.type not in CIRCULATION]
    if len(rooms) < 5 or any(s.type == "WC" for s in rooms):
        return
    offices = [s for s in rooms if s.type in ("office", "storage") and len(s.cells) == 1]
    if offices:
        s = min(offices, key=lambda s: ((s.cells[0][2] - s.cells[0][0]) * (s.cells[0][3] - s.cells[0][1]), s.id))
        counters["WC"] += 1
        s.type, s.name = "WC", f"WC_{counters['WC']}"
