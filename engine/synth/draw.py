"""Top view of a generated building: spaces coloured by ground truth, walls, openings, element boxes.

One panel per floor, in world metres relative to the building's origin (so a
UTM offset does not swamp the axis labels).  Drawn with matplotlib's Agg
backend from the plan, not the points, so it costs the same at any density.
"""
from __future__ import annotations

import math
import os
import uuid

import numpy as np

from engine.synth.building import Building

#: Edge colour of element boxes per class (structural surfaces are left out: they would hide the rest).
BOX_COLOURS = {"column": "#444444", "beam": "#888888", "table": "#b5651d", "chair": "#1f77b4", "sofa": "#9467bd",
               "bookcase": "#8c564b", "board": "#17becf", "clutter": "#7f7f7f", "wall": "#222222"}


def draw_plan(building: Building, path: str, *, counts: dict | None = None, dpi: int = 110) -> str:
    """Write the plan of every floor to ``path`` (PNG); returns the path."""
    import matplotlib
    from matplotlib.collections import LineCollection, PolyCollection
    from matplotlib.lines import Line2D

    fr = building.frame
    origin = np.asarray(building.origin()[:2])
    floors = sorted({s.floor for s in building.spaces})
    allxy = fr.xy(np.concatenate([s.footprint for s in building.spaces])) - origin
    span = allxy.max(0) - allxy.min(0) + 4
    per = float(np.clip(9.0 / max(span), 1 / 4.0, 0.5))  # inches per metre: readable at any size, at most 60 in
    per = min(per, 60.0 / max(span))
    w, h = max(4.0, span[0] * per), max(3.0, span[1] * per)
    font = float(np.clip(per * 24, 3.5, 8.0))
    from matplotlib.figure import Figure  # no pyplot: the caller's backend (a notebook's) is left alone

    fig = Figure(figsize=(w + 2.5, (h + 0.6) * len(floors) + 0.4))
    axes = fig.subplots(len(floors), 1, squeeze=False)
    cmap = matplotlib.colormaps["tab20"]
    for ax, f in zip(axes[:, 0], floors):
        spaces = [s for s in building.spaces if s.floor == f]
        polys = [fr.xy(s.footprint) - origin for s in spaces]
        ax.add_collection(PolyCollection(polys, facecolors=[cmap(s.id % 20) for s in spaces], alpha=0.45,
                                         edgecolors="none"))
        walls = [wl for wl in building.walls if wl.floor == f]
        ax.add_collection(PolyCollection([fr.xy(wl.body()) - origin for wl in walls], facecolors="#333333",
                                         edgecolors="none"))
        door_lines, window_lines = [], []
        for wl in walls:
            for o in wl.openings:
                a = np.asarray(wl.p0) + wl.direction * o.s0
                b = np.asarray(wl.p0) + wl.direction * o.s1
                (door_lines if o.kind == "door" else window_lines).append(fr.xy(np.array([a, b])) - origin)
        ax.add_collection(LineCollection(door_lines, colors="#ffcc00", linewidths=3.0))
        ax.add_collection(LineCollection(window_lines, colors="#00bfff", linewidths=2.0))
        boxes, colours = [], []
        for s in spaces:
            for e in s.elements:
                if e.cls not in BOX_COLOURS or (e.cls == "wall" and not e.info.get("partial")) \
                        or e.info.get("kind") == "light":
                    continue
                c, sz, yaw = e.center, e.size, e.yaw
                ca, sa = math.cos(yaw), math.sin(yaw)
                corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * sz[:2] / 2
                xy = corners @ np.array([[ca, sa], [-sa, ca]]) + c[:2]
                boxes.append(fr.xy(xy) - origin)
                colours.append(BOX_COLOURS[e.cls])
        ax.add_collection(PolyCollection(boxes, facecolors="none", edgecolors=colours, linewidths=0.7))
        for s, poly in zip(spaces, polys):
            scan = fr.xy(s.scanners[:, :2]) - origin
            ax.plot(scan[:, 0], scan[:, 1], "k+", ms=4, mew=0.8)
            label = s.name if counts is None else f"{s.name}\n{counts['spaces'].get(s.id, 0):,}"
            c = poly.mean(0)
            ax.text(c[0], c[1], label, fontsize=font, ha="center", va="center")
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.set_title(f"floor {f}", fontsize=9)
        ax.set_xlabel(f"x - {origin[0]:.0f} m", fontsize=8)
        ax.set_ylabel(f"y - {origin[1]:.0f} m", fontsize=8)
        ax.tick_params(labelsize=7)
    handles = [Line2D([], [], color=c, lw=2, label=k) for k, c in BOX_COLOURS.items()]
    handles += [Line2D([], [], color="#ffcc00", lw=3, label="door"), Line2D([], [], color="#00bfff", lw=2,
                                                                          label="window"),
                Line2D([], [], color="k", marker="+", lw=0, label="scanner")]
    fig.legend(handles=handles, loc="center right", fontsize=7, frameon=False)
    total = f", {sum(counts['spaces'].values()):,} points" if counts else ""
    fig.suptitle(f"synthetic building, seed {building.seed}: {len(building.spaces)} spaces, "
                 f"{building.floor_area:,.0f} m2{total}", fontsize=9)
    fig.tight_layout(rect=(0, 0, w / (w + 2.5), 0.97))
    path = os.fspath(path)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    tmp = os.path.join(os.path.dirname(os.path.abspath(path)), f".{os.path.basename(path)}.tmp-{uuid.uuid4().hex[:8]}.png")
    try:
        fig.savefig(tmp, dpi=dpi)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return path
