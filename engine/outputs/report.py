"""The run's report: ``report.html``, one self-contained page in the run's output folder.

It opens in a browser from the file system, with no server: the CSS is inline,
the floor plan (``floorplan.png``) is embedded as base64, and the other outputs
of the folder (``points.laz``, ``spaces.geojson``, ``elements.json``,
``metrics.json``, ``dask-report.html``) are linked by relative path when present.
Every string that comes from data goes through :func:`html.escape`.

Sections: the input; the floor plan; spaces (count, cells, ARI); the space
statistics table (:mod:`engine.outputs.statistics`: area, perimeter, points, element
counts per class, window-to-wall ratio); detection (per-class AP with and
without the CRF, point IoU) when there is ground truth; the CRF (spaces, solve
times, solver statuses); elements per class; timings per stage; provenance
(version, git commit, model and its SHA-256, non-default settings, input name,
size and SHA-256, start and end, cluster); the dask performance report.

``metrics.json``, which this page renders (other tools read it too)::

    {"input": {"path": str, "points": int},
     "spaces": {"count": int, "ari": float|null, "ari_oversegmented": float|null,
                "ari_before_update": float|null, "cells": int,
                "count_before_update": int,                          # optional
                "update": {"enabled": bool, "spaces_before": int, "spaces_after": int, "merges": int,
                           "splits": int, "evidence": bool, "pairs": int, "walls": int,
                           "kept": {reason: int}, "elements": {reconciliation counts}}},  # optional
     "detection": {"ap": {class: float}, "map": float, "structural_map": float, "furniture_map": float,
                   "ap_before_crf": {class: float}, "map_before_crf": float,
                   "ap_crf_ranked": {class: float}|null, "map_crf_ranked": float|null,
                   "iou": {class: float}, "miou": float} | null,          # null without ground truth
     "crf": {"spaces": int, "solve_seconds": {"median": float, "max": float},
             "status": {status_name: count},
             "proposals": int, "kept": int, "decides": [class, ...]},    # the last three optional
     "timings": {stage: seconds}, "elements": {class: count},
     "provenance": {...}}   # engine.pipeline.provenance; optional

Fractions (AP, IoU, ARI) are stored in [0, 1] and shown as percentages with
two decimals for AP and IoU (as in the paper's tables) and as fractions with
three decimals for ARI.  Missing values (``null``, NaN: a class without
ground truth) show as "n/a".  ``crf.status`` names are CP-SAT's (``OPTIMAL``,
``FEASIBLE``...) plus ``TRIVIAL`` (no edge left) and ``EMPTY`` (no proposal),
see :mod:`engine.crf.model`; any other status (``FEASIBLE``: best solution found
within the limits; ``UNKNOWN``...: the unary-only fallback) is called out under
the status table.  ``crf.proposals`` / ``crf.kept`` (optional) count the
proposals before and after the CRF; ``crf.decides`` (optional) names the classes
whose keep/drop the CRF decided (the others kept the detector's decision).
"""
from __future__ import annotations

import base64
import datetime as _dt
import html
import json
import math
import os
from collections.abc import Sequence
from typing import Any

from tiles.classes import ELEMENT_CLASSES

REPORT = "report.html"
#: CRF solver statuses of spaces solved exactly (see :mod:`engine.crf.model`).
SOLVED = ("OPTIMAL", "TRIVIAL", "EMPTY")
OUTPUTS = ("points.laz", "points.copc.laz", "spaces.geojson", "spaces.gpkg", "floorplan.png", "floorplan.svg",
           "building.ifc", "viewer.html", "elements.json", "metrics.json", "dask-report.html")

_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:2rem auto;max-width:72rem;
     padding:0 1rem;color:#222;line-height:1.4}
h1{font-size:1.6rem;margin-bottom:.2rem}h2{font-size:1.2rem;margin-top:2rem;border-bottom:1px solid #ddd}
.meta{color:#666;font-size:.9rem}
table{border-collapse:collapse;margin:.5rem 0;font-size:.9rem}
th,td{border:1px solid #ddd;padding:.25rem .6rem;text-align:right}
th{background:#f4f4f4}td:first-child,th:first-child{text-align:left}
tr.total td{font-weight:600;background:#fafafa}
img.plan{max-width:100%;border:1px solid #ddd}
.note{color:#666;font-size:.85rem}
.wide{overflow-x:auto}
.warning{color:#a33}
"""


def _esc(x: Any) -> str:
    return html.escape(printable(str(x)), quote=True)


def printable(s: str) -> str:
    """``s`` with the undecodable bytes of an OS path (surrogate escapes) shown as ``\\xNN``."""
    try:
        return s.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    except UnicodeEncodeError:  # other lone surrogates
        return s.encode("utf-8", "backslashreplace").decode("utf-8")


def _missing(v: Any) -> bool:
    return v is None or (isinstance(v, float) and math.isnan(v))


def fmt_int(v: Any) -> str:
    """An integer with thousands separators; "n/a" when missing."""
    return "n/a" if _missing(v) else f"{int(v):,}"


def fmt_float(v: Any, digits: int = 2) -> str:
    """A number with ``digits`` decimals; "n/a" when missing."""
    return "n/a" if _missing(v) else f"{float(v):.{digits}f}"


def fmt_pct(v: Any) -> str:
    """A fraction as a percentage with two decimals; "n/a" when missing."""
    return "n/a" if _missing(v) else f"{100 * float(v):.2f}"


class Html(str):
    """A table cell that is already HTML (a link made here), not escaped again."""


def _table(tid: str, header: Sequence[str], rows: Sequence[Sequence[str]], *, total: Sequence[str] | None = None,
           caption: str | None = None) -> str:
    """An HTML table; cells are already-formatted strings (escaped here)."""
    out = [f'<div class="wide"><table id="{_esc(tid)}">']
    if caption:
        out.append(f"<caption class=\"note\">{_esc(caption)}</caption>")
    out.append("<thead><tr>" + "".join(f"<th>{_esc(h)}</th>" for h in header) + "</tr></thead><tbody>")
    for r in rows:
        out.append("<tr>" + "".join(f"<td>{c if isinstance(c, Html) else _esc(c)}</td>" for c in r) + "</tr>")
    if total is not None:
        out.append('<tr class="total">' + "".join(f"<td>{_esc(c)}</td>" for c in total) + "</tr>")
    out.append("</tbody></table></div>")
    return "\n".join(out)


# -- sections --------------------------------------------------------------------------------------

def _input_section(m: dict[str, Any]) -> str:
    inp = m.get("input") or {}
    rows = [["input", str(inp.get("path", "n/a"))], ["points", fmt_int(inp.get("points"))]]
    return _table("input", ["", ""], rows)


def _spaces_section(m: dict[str, Any]) -> str:
    s = m.get("spaces") or {}
    rows = [["spaces", fmt_int(s.get("count"))]]
    if "count_before_update" in s:
        rows.append(["spaces before the space update", fmt_int(s.get("count_before_update"))])
    rows += [["cells (over-segmentation)", fmt_int(s.get("cells"))], ["ARI", fmt_float(s.get("ari"), 3)],
             ["ARI before the space update", fmt_float(s.get("ari_before_update"), 3)],
             ["ARI of the over-segmentation", fmt_float(s.get("ari_oversegmented"), 3)]]
    rows += _update_rows(s.get("update"))
    note = "" if not _missing(s.get("ari")) else '<p class="note">No ground truth: no ARI.</p>'
    return _table("spaces", ["", ""], rows) + note


def _update_rows(u: dict[str, Any] | None) -> list[list[str]]:
    """The space update's effect: merges, splits, why pairs stayed apart, elements reconciled."""
    if not u:
        return []
    if not u.get("enabled"):
        return [["space update", "off (--no-update)"]]
    kept = ", ".join(f"{k}: {v}" for k, v in (u.get("kept") or {}).items() if v)
    rows = [["space update", f"{fmt_int(u.get('merges'))} merges, {fmt_int(u.get('splits'))} splits"
                             + (" (merges need open faces)" if u.get("evidence") else " (paper's rule)")]]
    if kept:
        rows.append(["pairs kept apart by the update", kept])
    e = u.get("elements") or {}
    if e.get("merged_spaces"):
        rows.append(["elements reconciled in merged spaces",
                     f"{e.get('floors_joined', 0)} floors and {e.get('ceilings_joined', 0)} ceilings joined, "
                     f"{e.get('duplicates_suppressed', 0)} duplicates suppressed, "
                     f"{e.get('seam_walls_dropped', 0)} walls on removed dividers dropped"])
    return rows


def _stats_section(stats: dict[str, Any] | None, viewer: str | None = None) -> str:
    if not stats or not stats.get("spaces"):
        return '<p class="note">No space statistics (spaces.geojson or elements.json missing).</p>'
    total = stats["total"]
    classes = [c for c in ELEMENT_CLASSES if total["elements"].get(c, 0) > 0]
    lit = any(r.get("daylight_factor_pct") is not None for r in stats["spaces"])
    header = ["space", "area (m²)", "perimeter (m)", "height (m)", "points", *classes, "window/wall",
              *(["window/floor", "daylight factor (%)", "windows facing (°)"] if lit else [])]
    rows = []
    for r in stats["spaces"]:
        sid = (Html(f'<a href="{_esc(viewer)}#space={int(r["id"])}" title="open in the 3D view">{int(r["id"])}</a>')
               if viewer else str(r["id"]))
        rows.append([sid, fmt_float(r["area_m2"]), fmt_float(r["perimeter_m"]), fmt_float(r["height_m"]),
                     fmt_int(r["points"]), *[fmt_int(r["elements"][c]) for c in classes],
                     fmt_float(r["window_to_wall"], 3),
                     *([fmt_float(r.get("window_to_floor"), 3), fmt_float(r.get("daylight_factor_pct")),
                        ", ".join(f"{b:g}" for b in r.get("window_bearings_deg") or [])] if lit else [])])
    tot = ["total", fmt_float(total["area_m2"]), fmt_float(total["perimeter_m"]), "", fmt_int(total["points"]),
           *[fmt_int(total["elements"][c]) for c in classes], fmt_float(total["window_to_wall"], 3),
           *(["", "", ""] if lit else [])]
    note = ('<p class="note">Window/wall: summed face area (longer horizontal side × height) of the detected '
            'windows over that of the detected walls of the space.'
            + (' Daylight factor: the BRE average daylight factor (T 0.68, sky angle 90°, reflectance 0.5; '
               'engine/outputs/daylight.py); windows facing: the bearing of each window\'s outward normal '
               '(true north with a CRS, else grid north).' if lit else '') + '</p>')
    return _table("space-stats", header, rows, total=tot) + note


def _detection_section(m: dict[str, Any]) -> str:
    d = m.get("detection")
    if not d:
        return '<p class="note">No ground truth: no detection scores.</p>'
    ap, before, iou = d.get("ap") or {}, d.get("ap_before_crf") or {}, d.get("iou") or {}
    ranked = d.get("ap_crf_ranked") or {}
    rows = []
    for c in ELEMENT_CLASSES:
        a, b = ap.get(c), before.get(c)
        delta = None if _missing(a) or _missing(b) else float(a) - float(b)
        rows.append([c, fmt_pct(a), fmt_pct(b), fmt_pct(delta), fmt_pct(iou.get(c)), fmt_pct(ranked.get(c))])
    means = [["mAP", fmt_pct(d.get("map")), fmt_pct(d.get("map_before_crf")),
              fmt_pct(None if _missing(d.get("map")) or _missing(d.get("map_before_crf"))
                      else d["map"] - d["map_before_crf"]), fmt_pct(d.get("miou")), fmt_pct(d.get("map_crf_ranked"))],
             ["structural mAP", fmt_pct(d.get("structural_map")), "", "", "", ""],
             ["furniture mAP", fmt_pct(d.get("furniture_map")), "", "", "", ""]]
    return _table("detection", ["class", "AP (%)", "AP before CRF (%)", "CRF gain (points)", "point IoU (%)",
                                "AP ranked by CRF (%)"], rows + means,
                  caption="Pascal VOC AP at 3D IoU > 0.5; n/a: no ground truth of the class. AP: the final "
                          "elements (kept by the CRF). Before CRF: every proposal ranked by the detector's "
                          "score. Ranked by CRF: every proposal ranked by its score in context (engine.crf.model).")


def _crf_section(m: dict[str, Any]) -> str:
    c = m.get("crf")
    if not c:
        return '<p class="note">The CRF did not run.</p>'
    ss = c.get("solve_seconds") or {}
    rows = [["spaces", fmt_int(c.get("spaces"))]]
    if "proposals" in c:
        rows.append(["proposals", fmt_int(c.get("proposals"))])
    if "kept" in c:
        rows.append(["kept", fmt_int(c.get("kept"))])
    if "decides" in c:
        d = list(c.get("decides") or [])
        rows.append(["classes the CRF decides", ", ".join(d) if d else "none (every class keeps the detector's "
                     "decision, score > 0: the CRF beat it on no class of its training buildings)"])
    if c.get("always_kept"):
        rows.append(["always kept (a space's own, whatever their score)", ", ".join(c["always_kept"])])
    rows += [["solve seconds per space, median", fmt_float(ss.get("median"), 3)],
             ["solve seconds per space, max", fmt_float(ss.get("max"), 3)]]
    status = c.get("status") or {}
    srows = [[str(k), fmt_int(v)] for k, v in sorted(status.items())]
    out = _table("crf", ["", ""], rows) + _table("crf-status", ["solver status", "spaces"], srows)
    feasible = int(status.get("FEASIBLE", 0))
    failed = int(sum(v for k, v in status.items() if k not in SOLVED and k != "FEASIBLE"))
    if feasible or failed:
        out += ('<p class="note warning">Warning: '
                + _esc(f"{feasible + failed} space(s) not solved to optimality within the solver's limits "
                       f"(buildingparser.crf.deterministic-time / time-limit): {feasible} kept the best solution "
                       f"found (FEASIBLE), {failed} fell back to the detector's own decision (score > 0).")
                + "</p>")
    return out


def _elements_section(m: dict[str, Any]) -> str:
    e = m.get("elements") or {}
    names = [c for c in ELEMENT_CLASSES if c in e] + sorted(k for k in e if k not in ELEMENT_CLASSES)
    rows = [[c, fmt_int(e[c])] for c in names]
    return _table("elements", ["class", "elements"], rows, total=["total", fmt_int(sum(int(v) for v in e.values()))])


def _timings_section(m: dict[str, Any]) -> str:
    t = m.get("timings") or {}
    rows = [[str(k), fmt_float(v)] for k, v in t.items()]
    return _table("timings", ["stage", "seconds"], rows, total=["total", fmt_float(sum(float(v) for v in t.values()))])


def _provenance_section(metrics: dict[str, Any]) -> str:
    p = metrics.get("provenance")
    if not p:
        return '<p class="note">No provenance recorded.</p>'
    git, model, src, cl = p.get("git") or {}, p.get("model") or {}, p.get("input") or {}, p.get("cluster") or {}
    settings = {**{f"buildingparser.{k}": v for k, v in (p.get("settings") or {}).get("buildingparser", {}).items()},
                **{f"run: {k}": v for k, v in (p.get("settings") or {}).get("run", {}).items()}}
    rows = [["package", f"{p.get('package', 'buildingparser')} {p.get('version') or '(not installed)'}"],
            ["git commit", (git.get("commit", "") + (" (uncommitted changes)" if git.get("dirty") else ""))
             if git else "n/a"],
            ["model", f"{model.get('name', 'n/a')}" + (" (shipped default)" if model.get("default") else "")
             + (f"; chosen because {model['reason']}" if model.get("reason") else "")],
            *[[f"model sha256: {k}", v] for k, v in (model.get("sha256") or {}).items()],
            ["input", f"{src.get('name', 'n/a')}, {src.get('size', 0):,} bytes"
                      + (f", {src['files']} files" if src.get("files") else "")],
            ["input sha256", src.get("sha256") or "n/a"],
            ["started", p.get("started", "n/a")], ["ended", p.get("ended", "n/a")],
            ["cluster", ", ".join(f"{k} {v}" for k, v in cl.items())],
            *[[f"setting {k}", json.dumps(v)] for k, v in settings.items()]]
    if not settings:
        rows.append(["settings", "all defaults"])
    return _table("provenance", ["what", "value"], rows)


def _files_section(files: Sequence[str]) -> str:
    if not files:
        return ""
    items = "".join(f'<li><a href="{_esc(f)}">{_esc(f)}</a></li>' for f in files)
    return f"<ul>{items}</ul>"


def render_report(metrics: dict[str, Any], *, statistics: dict[str, Any] | None = None,
                  floorplan_png: bytes | None = None, floorplan_href: str | None = None,
                  files: Sequence[str] = (), dask_report: str | None = None, title: str | None = None,
                  viewer: str | None = None) -> str:
    """The report page as a string (see the module docstring).

    Parameters
    ----------
    metrics
        The ``metrics.json`` dict.
    statistics
        :func:`engine.outputs.statistics.space_statistics` output, or None.
    floorplan_png, floorplan_href
        The floor plan's PNG bytes (embedded) or a relative link to it; neither: no picture.
    files
        Output files to link (relative names).
    dask_report
        Relative name of the dask performance report, when there is one.
    viewer
        Relative name of the 3D view (``viewer.html``), when there is one: each space links to it.
    """
    inp = (metrics.get("input") or {}).get("path")
    title = title or f"buildingparser report: {os.path.basename(str(inp)) if inp else 'run'}"
    parts = [f"<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>{_esc(title)}</title>",
             f"<style>{_CSS}</style></head><body>", f"<h1>{_esc(title)}</h1>",
             f'<p class="meta">Written {_esc(_dt.datetime.now().isoformat(timespec="seconds"))} by buildingparser '
             f"(Armeni et al., 3D Semantic Parsing of Large-Scale Indoor Spaces, CVPR 2016).</p>",
             "<h2>Input</h2>", _input_section(metrics), "<h2>Floor plan</h2>"]
    if viewer:
        parts.append(f'<p><a href="{_esc(viewer)}">Open the 3D view</a> (points by class, space or colour; element '
                     "boxes; each space below links to it).</p>")
    if floorplan_png:
        data = base64.b64encode(floorplan_png).decode("ascii")
        parts.append(f'<img class="plan" alt="floor plan" src="data:image/png;base64,{data}">')
    elif floorplan_href:
        parts.append(f'<img class="plan" alt="floor plan" src="{_esc(floorplan_href)}">')
    else:
        parts.append('<p class="note">No floor plan picture.</p>')
    parts += ["<h2>Spaces</h2>", _spaces_section(metrics), "<h2>Space statistics</h2>", _stats_section(statistics, viewer),
              "<h2>Detection</h2>", _detection_section(metrics), "<h2>Contextual consistency (CRF)</h2>",
              _crf_section(metrics), "<h2>Elements</h2>", _elements_section(metrics),
              "<h2>Timings</h2>", _timings_section(metrics), "<h2>Provenance</h2>", _provenance_section(metrics),
              "<h2>Dask performance report</h2>"]
    if dask_report:
        parts.append(f'<p><a href="{_esc(dask_report)}">{_esc(dask_report)}</a> (task stream, worker profiles)</p>')
    else:
        parts.append('<p class="note">No dask performance report for this run.</p>')
    parts += ["<h2>Outputs</h2>", _files_section(files) or '<p class="note">none</p>', "</body></html>"]
    return "\n".join(parts)


def write_report(out_dir: str | os.PathLike, *, metrics: dict[str, Any], statistics: dict[str, Any] | None = None,
                 title: str | None = None, embed_floorplan: bool = True) -> str:
    """Write ``report.html`` into the run's output folder; returns its path.

    Parameters
    ----------
    out_dir
        The run's output folder (``floorplan.png``, ``spaces.geojson``, ``elements.json``,
        ``dask-report.html`` are picked up from it when present).
    metrics
        The ``metrics.json`` dict (the shape in the module docstring).
    statistics
        Space statistics; None computes them from ``spaces.geojson`` and ``elements.json`` when both exist.
    title
        The page title (default: from the input's file name).
    embed_floorplan
        Embed ``floorplan.png`` as base64 (self-contained page) rather than link it.
    """
    if not isinstance(metrics, dict):
        raise TypeError("metrics must be the metrics.json dict")
    out_dir = os.fspath(out_dir)
    if not os.path.isdir(out_dir):
        raise FileNotFoundError(f"no output folder {out_dir}")

    def here(name: str) -> str:
        return os.path.join(out_dir, name)

    if statistics is None and os.path.isfile(here("spaces.geojson")) and os.path.isfile(here("elements.json")):
        from engine.outputs.statistics import space_statistics

        with open(here("spaces.geojson")) as f:
            spaces = json.load(f)
        with open(here("elements.json")) as f:
            elements = json.load(f)
        statistics = space_statistics(spaces, elements)
    png = href = None
    if os.path.isfile(here("floorplan.png")):
        if embed_floorplan:
            with open(here("floorplan.png"), "rb") as f:
                png = f.read()
        else:
            href = "floorplan.png"
    files = [n for n in OUTPUTS if os.path.isfile(here(n))]
    page = render_report(metrics, statistics=statistics, floorplan_png=png, floorplan_href=href, files=files,
                         dask_report="dask-report.html" if os.path.isfile(here("dask-report.html")) else None,
                         title=title, viewer="viewer.html" if os.path.isfile(here("viewer.html")) else None)
    path = here(REPORT)
    tmp = path + ".tmp"
    with open(tmp, "w", encoding="utf-8", errors="backslashreplace") as f:
        f.write(page)
    os.replace(tmp, path)
    return path
