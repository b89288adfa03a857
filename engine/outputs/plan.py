"""The run's floor plan (``floorplan.png`` and ``floorplan.svg``): a plan an architect reads.

Drawn from the run's own outputs (the spaces layer and the final elements),
one panel per storey, in world coordinates (metres; the input's CRS when it
had one):

* spaces filled in pale colours and labelled with their id and area;
* the detected walls drawn as walls (their footprint: the box seen from above,
  at least ``MIN_WALL`` thick), not the dividers across the storey;
* doors as gaps in the wall with the leaf and its swing (a quarter circle of
  the door's width about the hinge, opening into the door's space);
* windows as thin glazed bands on their walls; columns solid; beams (above
  the cut plane) dashed;
* a scale bar, a north arrow when the CRS is known (grid north: the CRS's +y
  axis), a legend.

Furniture and clutter are left out, as on a plan.  Element boxes are
``center``, ``size`` (the box's extent along its own axes) and ``yaw`` (the
rotation of its own x axis about z), as in ``elements.json``.
"""
from __future__ import annotations

import math
import os
from collections.abc import Sequence
from typing import Any

import numpy as np

from engine.metrics.boxes import corners_2d, long_axis

#: Walls are drawn at least this thick (m), so a 2 cm detected plane still reads as a wall.
MIN_WALL = 0.10
#: A door's gap is cut this deep across its wall (m): through walls up to this thickness.
DOOR_CUT = 0.45
#: Classes drawn on the plan, in drawing order.
PLAN_CLASSES = ("wall", "column", "window", "door", "beam")
COLOURS = {"wall": "0.15", "column": "0.05", "window": "#5fa8d3", "door": "#b5651d", "beam": "0.35"}


def footprint(center: Sequence[float], size: Sequence[float], yaw: float, *, min_thickness: float = 0.0
              ) -> np.ndarray:
    """The ``(4, 2)`` corners (counter-clockwise) of a box's top view; its thinner horizontal side is at least
    ``min_thickness``."""
    dx, dy = max(float(size[0]), 0.0), max(float(size[1]), 0.0)
    if dx <= dy:
        dx = max(dx, min_thickness)
    else:
        dy = max(dy, min_thickness)
    return corners_2d(np.array([center[0], center[1], 0.0, dx, dy, 0.0, yaw], dtype=float))


def door_swing(door: dict[str, Any], towards: Sequence[float] | None = None) -> dict[str, Any]:
    """A door's plan symbol: hinge, width, the leaf's open end and the swing's angles (degrees).

    The hinge is at one end of the door's long horizontal side; the leaf opens
    through 90 degrees to the side of ``towards`` (the door's space), or to the
    box's +normal side without it.
    """
    axis, width = long_axis(door["size"], float(door["yaw"]))
    normal = np.array([-axis[1], axis[0]])
    center = np.asarray(door["center"][:2], dtype=float)
    if towards is not None and float(np.dot(np.asarray(towards[:2], float) - center, normal)) < 0:
        normal = -normal
    hinge = center - axis * width / 2
    closed = math.degrees(math.atan2(axis[1], axis[0]))
    opened = math.degrees(math.atan2(normal[1], normal[0]))
    turn = (opened - closed + 180) % 360 - 180  # +90 or -90
    start, end = (closed, closed + turn) if turn > 0 else (closed + turn, closed)
    return {"hinge": hinge, "width": width, "leaf_end": hinge + normal * width, "theta": (start, end),
            "axis": axis, "normal": normal}


def scale_length(span: float) -> float:
    """A round scale bar length (1, 2 or 5 x 10^k m) near a fifth of ``span`` metres."""
    target = max(span / 5.0, 1e-6)
    k = 10 ** math.floor(math.log10(target))
    return float(max(m * k for m in (1, 2, 5) if m * k <= target) if target >= k else k)


def storeys(spaces: dict[str, Any]) -> list[int]:
    """The storeys of a spaces layer, in order."""
    return sorted({int(f["properties"].get("floor", 0)) for f in spaces.get("features", [])}) or [0]


def draw_plan(spaces: dict[str, Any], elements: list[dict[str, Any]], png: str | os.PathLike | None = None,
              svg: str | os.PathLike | None = None, *, crs_known: bool = False, dpi: int = 150) -> dict[str, Any]:
    """Draw the plan to ``png`` and/or ``svg``; returns the figure and, per storey, what was drawn.

    ``spaces`` is a GeoJSON FeatureCollection as ``spaces.geojson``; ``elements``
    the records of ``elements.json``.
    """
    from matplotlib.figure import Figure  # no pyplot: a notebook's backend is left alone

    floors = storeys(spaces)
    bounds = _bounds(spaces, elements)
    w, h = bounds[2] - bounds[0], bounds[3] - bounds[1]
    width_in = 9.0
    fig = Figure(figsize=(width_in, max(3.0, width_in * h / max(w, 1e-9)) * len(floors) + 0.8))
    axes = fig.subplots(len(floors), 1, squeeze=False)
    space_floor = {int(f["properties"]["id"]): int(f["properties"].get("floor", 0)) for f in spaces["features"]}
    centroids = _centroids(spaces)
    drawn = {}
    for ax, floor in zip(axes[:, 0], floors):
        mine = [e for e in elements if space_floor.get(int(e.get("space_id", -1)), floors[0]) == floor]
        drawn[floor] = _draw_storey(ax, spaces, mine, floor, centroids)
        ax.set_xlim(bounds[0] - 0.05 * w, bounds[2] + 0.05 * w)
        ax.set_ylim(bounds[1] - 0.05 * h, bounds[3] + 0.05 * h)
        ax.set_aspect("equal")
        ax.ticklabel_format(useOffset=False, style="plain")  # world coordinates as they are (UTM: 6-7 digits)
        ax.tick_params(labelsize=6)
        _scale_bar(ax, w)
        if crs_known:
            _north_arrow(ax)
    _legend(fig)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    import matplotlib

    for path in (png, svg):
        if path:
            path = os.fspath(path)
            os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
            with matplotlib.rc_context({"svg.fonttype": "none"}):  # the SVG's labels stay text, editable
                fig.savefig(path, dpi=dpi)
    return {"figure": fig, "storeys": drawn}


def _bounds(spaces: dict[str, Any], elements: list[dict[str, Any]]) -> tuple[float, float, float, float]:
    xs, ys = [], []
    for f in spaces.get("features", []):
        for ring in _rings(f["geometry"]):
            a = np.asarray(ring, float)
            xs += [a[:, 0].min(), a[:, 0].max()]
            ys += [a[:, 1].min(), a[:, 1].max()]
    for e in elements:
        xs.append(e["center"][0])
        ys.append(e["center"][1])
    if not xs:
        return (0.0, 0.0, 1.0, 1.0)
    return (min(xs), min(ys), max(xs), max(ys))


def _rings(geometry: dict[str, Any]) -> list[list[list[float]]]:
    if not geometry or not geometry.get("coordinates"):
        return []
    if geometry["type"] == "Polygon":
        return [geometry["coordinates"][0]]
    if geometry["type"] == "MultiPolygon":
        return [p[0] for p in geometry["coordinates"]]
    return []


def _centroids(spaces: dict[str, Any]) -> dict[int, np.ndarray]:
    from shapely.geometry import shape

    out = {}
    for f in spaces.get("features", []):
        if f.get("geometry") and f["geometry"].get("coordinates"):
            p = shape(f["geometry"]).representative_point()
            out[int(f["properties"]["id"])] = np.array([p.x, p.y])
    return out


def _draw_storey(ax, spaces: dict[str, Any], elements: list[dict[str, Any]], floor: int,
                 centroids: dict[int, np.ndarray]) -> dict[str, int]:
    import matplotlib
    from matplotlib.patches import Arc, Polygon

    pale = matplotlib.colormaps["Pastel1"](np.arange(9))
    counts = dict.fromkeys(("spaces",) + PLAN_CLASSES, 0)
    for f in spaces["features"]:
        p = f["properties"]
        if int(p.get("floor", 0)) != floor:
            continue
        for ring in _rings(f["geometry"]):
            ax.add_patch(Polygon(np.asarray(ring)[:, :2], closed=True, facecolor=pale[int(p["id"]) % 9],
                                 edgecolor="0.7", lw=0.4, zorder=1))
        if int(p["id"]) in centroids:
            c = centroids[int(p["id"])]
            ax.text(c[0], c[1], f"{p['id']}\n{float(p.get('area_m2', 0)):.1f} m²", fontsize=6, ha="center",
                    va="center", zorder=6, bbox={"facecolor": "white", "alpha": 0.7, "edgecolor": "none", "pad": 1})
        counts["spaces"] += 1
    by_class: dict[str, list[dict[str, Any]]] = {k: [] for k in PLAN_CLASSES}
    for e in elements:
        if e["class"] in by_class:
            by_class[e["class"]].append(e)
    for e in by_class["wall"]:
        ax.add_patch(Polygon(footprint(e["center"], e["size"], e["yaw"], min_thickness=MIN_WALL), closed=True,
                             facecolor=COLOURS["wall"], edgecolor="none", zorder=3))
    for e in by_class["column"]:
        ax.add_patch(Polygon(footprint(e["center"], e["size"], e["yaw"]), closed=True, facecolor=COLOURS["column"],
                             edgecolor="none", zorder=3))
    for e in by_class["beam"]:
        ax.add_patch(Polygon(footprint(e["center"], e["size"], e["yaw"]), closed=True, fill=False, ls="--", lw=0.6,
                             edgecolor=COLOURS["beam"], zorder=2))
    for e in by_class["window"]:
        ax.add_patch(Polygon(footprint(e["center"], e["size"], e["yaw"], min_thickness=MIN_WALL), closed=True,
                             facecolor="white", edgecolor=COLOURS["window"], lw=0.8, zorder=4))
    for e in by_class["door"]:
        sw = door_swing(e, centroids.get(int(e.get("space_id", -1))))
        cut = np.array([sw["hinge"] - sw["normal"] * DOOR_CUT / 2, sw["hinge"] + sw["axis"] * sw["width"]
                        - sw["normal"] * DOOR_CUT / 2, sw["hinge"] + sw["axis"] * sw["width"] + sw["normal"]
                        * DOOR_CUT / 2, sw["hinge"] + sw["normal"] * DOOR_CUT / 2])
        ax.add_patch(Polygon(cut, closed=True, facecolor="white", edgecolor="none", zorder=4))
        ax.plot(*np.stack([sw["hinge"], sw["leaf_end"]]).T, color=COLOURS["door"], lw=0.8, zorder=5)
        ax.add_patch(Arc(sw["hinge"], 2 * sw["width"], 2 * sw["width"], theta1=sw["theta"][0], theta2=sw["theta"][1],
                         color=COLOURS["door"], lw=0.5, zorder=5))
    for k in PLAN_CLASSES:
        counts[k] = len(by_class[k])
    ax.set_title(f"storey {floor}: {counts['spaces']} spaces", fontsize=9)
    return counts


def _scale_bar(ax, span: float) -> None:
    from matplotlib.font_manager import FontProperties
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    length = scale_length(span)
    label = f"{length:g} m"
    ax.add_artist(AnchoredSizeBar(ax.transData, length, label, "lower left", pad=0.4, frameon=False,
                                  size_vertical=length / 25, fontproperties=FontProperties(size=6)))


def _north_arrow(ax) -> None:
    ax.annotate("N", xy=(0.96, 0.95), xytext=(0.96, 0.82), xycoords="axes fraction", ha="center", va="center",
                fontsize=8, arrowprops={"arrowstyle": "-|>", "color": "black", "lw": 1.0}, zorder=7)


def _legend(fig) -> None:
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [Patch(facecolor="#fbb4ae", edgecolor="0.7", label="space (id, area)"),
               Patch(facecolor=COLOURS["wall"], label="wall"), Patch(facecolor=COLOURS["column"], label="column"),
               Patch(facecolor="white", edgecolor=COLOURS["window"], label="window"),
               Line2D([], [], color=COLOURS["door"], lw=0.8, label="door (leaf, swing)"),
               Patch(fill=False, ls="--", edgecolor=COLOURS["beam"], label="beam (above)")]
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=6, frameon=False)
