"""The interactive 3D view, ``viewer.html``: one self-contained page that opens offline from the file.

Made with plotly (its WebGL ``scatter3d``; plotly.js is bundled into the page,
so no server and no network are needed).  What it shows:

* the points, subsampled evenly per space to at most ``buildingparser.viewer.
  max-points`` in all (each space gets an equal share, a space with fewer
  points keeps them all and leaves its share to the others; points outside
  every space get one share), coloured by class (a legend entry per class),
  by space or by the scan's RGB (buttons switch the three); the ceiling's
  points start hidden, so that the rooms show from above;
* the element boxes, one legend entry per class, with class, element id,
  space and score on hover;
* the legend switches every layer on and off; ``viewer.html#space=ID`` opens
  with that space alone (``report.html`` links each space so).

The subsample is drawn on the workers, one task per tile, with a fixed seed:
the same run gives the same page.
"""
from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any

import numpy as np

from engine.metrics.boxes import corners_2d
from tiles.classes import CLASS_NAMES
from tiles.store import TileStore
from tiles.tasks import run_tasks

if TYPE_CHECKING:
    from distributed import Client

#: Colours of the classes (S3DIS order), as in the paper's figures' spirit: structure muted, furniture bright.
CLASS_COLOURS = ("#c7c7c7", "#8c6d31", "#9e9ac8", "#636363", "#393b79", "#6baed6", "#e6550d", "#31a354",
                 "#fdae6b", "#d62728", "#8c564b", "#17becf", "#bdbdbd")
#: Classes whose points start hidden (a click in the legend shows them): the ceiling hides the rooms from above.
HIDDEN_AT_START = ("ceiling",)
SEED = 20161  # fixed: the same run gives the same page
#: Box edges as pairs of corner indices (corners in ``_corners`` order).
EDGES = ((0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7))


def sample_rates(space_counts: dict[int, int], budget: int) -> dict[int, float]:
    """Per space (``-1``: outside every space), the fraction of its points kept so that the spaces share
    ``budget`` points evenly (water-filling: a small space keeps all and leaves the rest to the others)."""
    left, todo, rates = float(budget), dict(space_counts), {}
    while todo:
        share = left / len(todo)
        small = {s: n for s, n in todo.items() if n <= share}
        if not small:
            rates.update({s: share / n for s, n in todo.items()})
            break
        for s, n in small.items():
            rates[s] = 1.0
            left -= n
            del todo[s]
    return {s: min(1.0, r) for s, r in rates.items()}


def _tile_sample(tile: str, store, rates: dict[int, float], colour: bool) -> dict[str, np.ndarray]:
    """One tile's sample: world xyz (float32), space, class and RGB (8 bit) of the kept points."""
    names = ["space_id", "classification"] + (["red", "green", "blue"] if colour else [])
    cols = store.read(tile, names)
    space = cols["space_id"].astype(np.int64)
    rate = np.array([rates.get(int(s), 0.0) for s in np.unique(space)])
    keep_rate = rate[np.searchsorted(np.unique(space), space)]
    seed = SEED + sum(tile.encode())
    keep = np.random.default_rng(seed).random(len(space)) < keep_rate
    xyz = store.xyz(tile, local=False)[keep]
    out = {"xyz": xyz.astype(np.float32), "space": space[keep].astype(np.int32),
           "cls": cols["classification"][keep].astype(np.uint8)}
    if colour:
        depth = 8 if store.meta.color_depth == 8 else 16
        rgb = np.stack([cols[c][keep] for c in ("red", "green", "blue")], axis=1).astype(np.int64)
        out["rgb"] = (rgb if depth == 8 else rgb >> 8).clip(0, 255).astype(np.uint8)
    return out


def viewer_points(store: TileStore, space_counts: dict[int, int], budget: int, *, client: Client | None = None
                  ) -> dict[str, np.ndarray]:
    """The viewer's subsample of the store's points, evenly per space (see :func:`sample_rates`)."""
    rates = sample_rates(space_counts, budget)
    colour = all(n in store.meta.names() for n in ("red", "green", "blue"))
    tiles = [t.name for t in store.tiles]
    parts = run_tasks(_tile_sample, tiles, client=client, label="viewer sample", keys=tiles,
                      extra_args=(store, rates, colour))
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]} if parts else {}


def space_palette() -> list[str]:
    """40 distinct colours for spaces (matplotlib's tab20 and tab20b), as hex."""
    import matplotlib
    from matplotlib.colors import to_hex

    return [to_hex(c) for name in ("tab20", "tab20b") for c in matplotlib.colormaps[name](np.arange(20))]


def _corners(e: dict[str, Any]) -> np.ndarray:
    """The 8 corners of an element's box: its footprint at the bottom, then at the top."""
    xy = corners_2d(np.array([*e["center"], *e["size"], e["yaw"]], dtype=float))
    z0, z1 = e["center"][2] - e["size"][2] / 2, e["center"][2] + e["size"][2] / 2
    return np.vstack([np.c_[xy, np.full(4, z0)], np.c_[xy, np.full(4, z1)]])


def _box_trace(go, cls: str, boxes: list[dict[str, Any]], colour: str):
    xs, ys, zs, text = [], [], [], []
    for e in boxes:
        c = _corners(e)
        label = f"{cls} #{e['element_id']}<br>space {e['space_id']}<br>score {float(e['score']):.2f}"
        for a, b in EDGES:
            xs += [c[a, 0], c[b, 0], None]
            ys += [c[a, 1], c[b, 1], None]
            zs += [c[a, 2], c[b, 2], None]
            text += [label, label, None]
    return go.Scatter3d(x=xs, y=ys, z=zs, mode="lines", line={"color": colour, "width": 3}, name=f"{cls} boxes",
                        legendgroup="boxes", legendgrouptitle={"text": "elements"}, hovertext=text,
                        hoverinfo="text", meta={"layer": "boxes"})


def viewer_figure(points: dict[str, np.ndarray], elements: list[dict[str, Any]],
                  outlines: dict[int, dict[str, Any]] | None = None):
    """The plotly figure: point traces per class (buttons recolour them by space or by RGB), box traces per
    class, space outlines; coordinates relative to the sample's lower corner (printed in the title)."""
    import plotly.graph_objects as go

    fig = go.Figure()
    xyz64 = points.get("xyz", np.zeros((0, 3), np.float32)).astype(np.float64)
    origin = xyz64.min(axis=0) if len(xyz64) else np.zeros(3)
    xyz = (xyz64 - origin).astype(np.float32)
    palette = space_palette()
    by_space, by_rgb, point_traces = [], [], []
    for code in np.unique(points.get("cls", np.zeros(0, np.uint8))):
        m = points["cls"] == code
        p = xyz[m]
        name = CLASS_NAMES[int(code)] if code < len(CLASS_NAMES) else f"class {code}"
        fig.add_trace(go.Scatter3d(x=p[:, 0], y=p[:, 1], z=p[:, 2], mode="markers", name=name,
                                   marker={"size": 1.6, "color": CLASS_COLOURS[int(code) % len(CLASS_COLOURS)]},
                                   hoverinfo="name", legendgroup="points", legendgrouptitle={"text": "points"},
                                   visible="legendonly" if name in HIDDEN_AT_START else True,
                                   meta={"layer": "points"}))
        point_traces.append(len(fig.data) - 1)
        by_space.append([palette[int(s) % len(palette)] if s >= 0 else "#999999" for s in points["space"][m]])
        if "rgb" in points:
            rgb = points["rgb"][m].astype(np.int64)
            by_rgb.append([f"#{v:06x}" for v in (rgb[:, 0] << 16 | rgb[:, 1] << 8 | rgb[:, 2])])
    for code, cls in enumerate(CLASS_NAMES):
        boxes = [dict(e, center=list(np.asarray(e["center"]) - origin)) for e in elements if e["class"] == cls]
        if boxes:
            fig.add_trace(_box_trace(go, cls, boxes, CLASS_COLOURS[code]))
    for sid, outline in sorted((outlines or {}).items()):
        r = np.asarray(outline["ring"], dtype=np.float64) - origin
        fig.add_trace(go.Scatter3d(x=r[:, 0], y=r[:, 1], z=r[:, 2], mode="lines", name=f"space {sid}",
                                   line={"color": palette[sid % len(palette)], "width": 4}, hoverinfo="name",
                                   legendgroup="spaces", legendgrouptitle={"text": "spaces"},
                                   meta={"layer": "space", "space": int(sid), "height": outline["height"]}))
    class_colours = [CLASS_COLOURS[int(c) % len(CLASS_COLOURS)] for c in np.unique(points.get("cls", []))]
    buttons = [{"label": "colour by class", "method": "restyle", "args": [{"marker.color": class_colours},
                                                                          point_traces]},
               {"label": "by space", "method": "restyle", "args": [{"marker.color": by_space}, point_traces]}]
    if by_rgb:
        buttons.append({"label": "by RGB", "method": "restyle", "args": [{"marker.color": by_rgb}, point_traces]})
    fig.update_layout(scene={"aspectmode": "data", "xaxis_title": "x (m)", "yaxis_title": "y (m)",
                             "zaxis_title": "z (m)"},
                      updatemenus=[{"buttons": buttons, "direction": "right", "x": 0.0, "y": 1.06,
                                    "xanchor": "left"}] if point_traces else [],
                      margin={"l": 0, "r": 0, "t": 40, "b": 0}, legend={"groupclick": "toggleitem"},
                      title={"text": f"{len(xyz):,} points shown; coordinates relative to "
                                     f"{np.round(origin, 2).tolist()}", "x": 0.01, "xanchor": "left",
                             "y": 0.02, "yanchor": "bottom", "font": {"size": 11}})
    return fig


#: ``viewer.html#space=ID``: zoom the scene to that space's outline (points outside the axes' ranges are hidden).
_HASH_SCRIPT = """
var gd = document.getElementById('{plot_id}');
function bpShowSpace() {
  var m = /space=(-?\\d+)/.exec(window.location.hash || '');
  if (!m) return;
  var t = gd.data.filter(function (d) { return d.meta && d.meta.layer === 'space' && d.meta.space == m[1]; })[0];
  if (!t) return;
  function range(a) { var lo = Math.min.apply(null, a), hi = Math.max.apply(null, a), pad = 0.3;
                      return [lo - pad, hi + pad]; }
  var z = range(t.z);
  Plotly.relayout(gd, {'scene.xaxis.range': range(t.x), 'scene.yaxis.range': range(t.y),
                       'scene.zaxis.range': [z[0] - 0.2, z[0] + (t.meta.height || 3.5)],
                       'scene.aspectmode': 'data'});
}
bpShowSpace();
window.addEventListener('hashchange', bpShowSpace);
"""


def space_outlines(layer: dict[str, Any]) -> dict[int, dict[str, Any]]:
    """Per space, its footprint's exterior ring at its floor height (``ring``, ``(n, 3)``) and its ``height``
    (from ``spaces.geojson``)."""
    out = {}
    for f in layer.get("features", []):
        g, p = f.get("geometry") or {}, f["properties"]
        rings = ([g["coordinates"][0]] if g.get("type") == "Polygon" else
                 [q[0] for q in g["coordinates"]] if g.get("type") == "MultiPolygon" else [])
        if rings:
            ring = np.asarray(max(rings, key=len), dtype=np.float64)[:, :2]
            z0 = float(p.get("z_min", 0.0))
            out[int(p["id"])] = {"ring": np.c_[ring, np.full(len(ring), z0)],
                                 "height": float(p.get("z_max", z0 + 3.0)) - z0}
    return out


def write_viewer(path: str | os.PathLike, points: dict[str, np.ndarray], elements: list[dict[str, Any]],
                 layer: dict[str, Any] | None = None) -> str:
    """Write ``viewer.html`` (plotly.js inlined: it opens offline); returns the path."""
    import plotly.io as pio

    fig = viewer_figure(points, elements, space_outlines(layer or {}))
    html = pio.to_html(fig, include_plotlyjs=True, full_html=True, post_script=_HASH_SCRIPT,
                       config={"displaylogo": False, "responsive": True}, div_id="bp-viewer")
    path = os.fspath(path)
    tmp = path + ".tmp"
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(html.replace("<head>", '<head><title>buildingparser: 3D view</title>', 1))
    os.replace(tmp, path)
    return path


def viewer_summary(points: dict[str, np.ndarray]) -> dict[str, Any]:
    """How many points the page shows, in all and per space (JSON-ready)."""
    if not points:
        return {"points": 0, "per_space": {}}
    ids, n = np.unique(points["space"], return_counts=True)
    return {"points": int(len(points["space"])), "per_space": {int(i): int(c) for i, c in zip(ids, n)}}


def space_counts_from_layer(layer: dict[str, Any], total: int) -> dict[int, int]:
    """Points per space from a spaces layer's ``point_count``; the rest of ``total`` is outside every space."""
    counts = {int(f["properties"]["id"]): int(f["properties"].get("point_count", 0)) for f in layer["features"]}
    counts[-1] = max(0, int(total) - sum(counts.values()))
    return {k: v for k, v in counts.items() if v > 0}

