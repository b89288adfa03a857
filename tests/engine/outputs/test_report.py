"""The run's report.html: self-contained, escaped, and its tables say what metrics.json says."""
from __future__ import annotations

import base64
import json
import math
from html.parser import HTMLParser

import pytest

from engine.outputs.report import render_report, write_report
from engine.outputs.statistics import space_statistics
from tiles.classes import ELEMENT_CLASSES

METRICS = {
    "input": {"path": "/data/<script>alert(1)</script> & co.laz", "points": 1234567},
    "spaces": {"count": 12, "ari": 0.8765, "ari_oversegmented": 0.5432, "ari_before_update": 0.7012, "cells": 57,
               "count_before_update": 15},
    "detection": {"ap": {c: 0.05 * (i + 1) for i, c in enumerate(ELEMENT_CLASSES)} | {"beam": float("nan")},
                  "map": 0.4567, "structural_map": 0.5, "furniture_map": 0.3976,
                  "ap_before_crf": {c: 0.04 * (i + 1) for i, c in enumerate(ELEMENT_CLASSES)} | {"beam": None},
                  "map_before_crf": 0.4012, "iou": {c: 0.5 + 0.01 * i for i, c in enumerate(ELEMENT_CLASSES)},
                  "miou": 0.5512},
    "crf": {"spaces": 12, "solve_seconds": {"median": 0.0412, "max": 1.9},
            "status": {"OPTIMAL": 11, "FEASIBLE": 1}, "proposals": 900, "kept": 412, "decides": ["wall", "door"],
            "always_kept": ["ceiling", "floor"]},
    "timings": {"ingest": 12.5, "spaces": 30.25, "detection": 100.0, "crf": 4.75},
    "elements": {"wall": 40, "chair": 35, "window": 5},
}


class Tables(HTMLParser):
    """Text of every table cell by table id; images and links."""

    def __init__(self):
        super().__init__()
        self.tables, self.images, self.links, self.tags = {}, [], [], []
        self._table = self._row = self._cell = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.append(tag)
        if tag == "table":
            self._table = self.tables.setdefault(a.get("id"), [])
        elif tag == "tr" and self._table is not None:
            self._row = []
            self._table.append(self._row)
        elif tag in ("td", "th") and self._row is not None:
            self._cell = []
        elif tag == "img":
            self.images.append(a.get("src", ""))
        elif tag == "a":
            self.links.append(a.get("href"))

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self._row.append("".join(self._cell))
            self._cell = None
        elif tag == "table":
            self._table = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)


def parse(page):
    p = Tables()
    p.feed(page)
    return p


def rows(table):
    """``{first cell: [other cells]}`` of a parsed table (header row included)."""
    return {r[0]: r[1:] for r in table}


def num(text):
    return None if text == "n/a" else float(text.replace(",", ""))


def test_report_tables_match_metrics():
    p = parse(render_report(METRICS))
    det = rows(p.tables["detection"])
    for c in ELEMENT_CLASSES:
        ap, before = METRICS["detection"]["ap"][c], METRICS["detection"]["ap_before_crf"][c]
        shown = det[c]
        if ap is None or math.isnan(ap):
            assert shown[0] == "n/a" and shown[2] == "n/a"
        else:
            assert num(shown[0]) == pytest.approx(100 * ap, abs=0.005)
            assert num(shown[1]) == pytest.approx(100 * before, abs=0.005)
            assert num(shown[2]) == pytest.approx(100 * (ap - before), abs=0.01)
        assert num(shown[3]) == pytest.approx(100 * METRICS["detection"]["iou"][c], abs=0.005)
    assert num(det["mAP"][0]) == pytest.approx(45.67) and num(det["mAP"][1]) == pytest.approx(40.12)
    assert num(det["mAP"][3]) == pytest.approx(55.12)
    assert num(det["furniture mAP"][0]) == pytest.approx(39.76)
    assert all(det[c][4] == "n/a" for c in ELEMENT_CLASSES)  # no CRF ranking in these metrics
    ranked = {**METRICS["detection"], "ap_crf_ranked": {c: 0.25 for c in ELEMENT_CLASSES}, "map_crf_ranked": 0.3}
    det2 = rows(parse(render_report({**METRICS, "detection": ranked})).tables["detection"])
    assert num(det2["wall"][4]) == pytest.approx(25.0) and num(det2["mAP"][4]) == pytest.approx(30.0)

    sp = rows(p.tables["spaces"])
    assert num(sp["spaces"][0]) == 12 and num(sp["cells (over-segmentation)"][0]) == 57
    assert num(sp["ARI"][0]) == pytest.approx(0.8765, abs=5e-4)
    assert num(sp["ARI before the space update"][0]) == pytest.approx(0.7012, abs=5e-4)
    assert num(sp["ARI of the over-segmentation"][0]) == pytest.approx(0.5432, abs=5e-4)
    assert num(sp["spaces before the space update"][0]) == 15

    crf = rows(p.tables["crf"])
    assert num(crf["spaces"][0]) == 12 and num(crf["proposals"][0]) == 900 and num(crf["kept"][0]) == 412
    assert num(crf["solve seconds per space, median"][0]) == pytest.approx(0.0412, abs=5e-4)
    assert num(crf["solve seconds per space, max"][0]) == pytest.approx(1.9)
    assert crf["classes the CRF decides"][0] == "wall, door"
    none = rows(parse(render_report(dict(METRICS, crf=dict(METRICS["crf"], decides=[])))).tables["crf"])
    assert none["classes the CRF decides"][0].startswith("none")
    assert crf["always kept (a space's own, whatever their score)"][0] == "ceiling, floor"
    status = rows(p.tables["crf-status"])
    assert {k: num(v[0]) for k, v in status.items() if k != "solver status"} == {"OPTIMAL": 11, "FEASIBLE": 1}

    tim = rows(p.tables["timings"])
    for stage, secs in METRICS["timings"].items():
        assert num(tim[stage][0]) == pytest.approx(secs, abs=0.005)
    assert num(tim["total"][0]) == pytest.approx(sum(METRICS["timings"].values()))
    el = rows(p.tables["elements"])
    assert {k: num(v[0]) for k, v in el.items() if k not in ("class", "total")} == METRICS["elements"]
    assert num(rows(p.tables["input"])["points"][0]) == 1234567


def test_strings_are_escaped():
    page = render_report(METRICS)
    p = parse(page)
    assert "script" not in p.tags  # the path's <script> is text, not a tag
    assert "&lt;script&gt;" in page
    assert rows(p.tables["input"])["input"][0] == METRICS["input"]["path"]  # and reads back as the same text


def test_no_ground_truth_and_missing_sections():
    m = {"input": {"path": "a.laz", "points": 10}, "spaces": {"count": 2, "ari": None, "ari_oversegmented": None,
                                                              "ari_before_update": None, "cells": 3},
         "detection": None, "crf": {"spaces": 2, "solve_seconds": {"median": 0.1, "max": 0.2}, "status": {"OPTIMAL": 2}},
         "timings": {}, "elements": {}}
    page = render_report(m)
    p = parse(page)
    assert "detection" not in p.tables and "No ground truth" in page
    assert rows(p.tables["spaces"])["ARI"][0] == "n/a"
    assert "spaces before the space update" not in rows(p.tables["spaces"])  # optional: absent, not "n/a"
    assert "not solved to optimality" not in page  # every space OPTIMAL: no warning


def test_spaces_not_solved_to_optimality_are_called_out():
    m = dict(METRICS, crf=dict(METRICS["crf"], status={"OPTIMAL": 9, "FEASIBLE": 2, "UNKNOWN": 1}))
    text = " ".join(render_report(m).split())
    assert "Warning: 3 space(s) not solved to optimality" in text
    assert "2 kept the best solution found (FEASIBLE), 1 fell back" in text
    text = " ".join(render_report(dict(METRICS, crf=dict(METRICS["crf"], status={"OPTIMAL": 3, "TRIVIAL": 2,
                                                                               "EMPTY": 1}))).split())
    assert "not solved to optimality" not in text


def test_write_report_is_self_contained(tmp_path):
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(1, 1))
    ax.plot([0, 1], [0, 1])
    fig.savefig(tmp_path / "floorplan.png")
    plt.close(fig)
    spaces = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "id": 0, "geometry": {"type": "Polygon",
                                                  "coordinates": [[[0, 0], [4, 0], [4, 5], [0, 5], [0, 0]]]},
         "properties": {"id": 0, "point_count": 500, "z_min": 0, "z_max": 3}}]}
    elements = [{"class": "wall", "class_code": 2, "space_id": 0, "center": [0, 0, 1.5], "size": [4, 0.2, 3],
                 "yaw": 0.0},
                {"class": "window", "class_code": 5, "space_id": 0, "center": [0, 0, 1.5], "size": [1, 0.1, 1.2],
                 "yaw": 0.0}]
    (tmp_path / "spaces.geojson").write_text(json.dumps(spaces))
    (tmp_path / "elements.json").write_text(json.dumps(elements))
    (tmp_path / "metrics.json").write_text(json.dumps(METRICS))
    (tmp_path / "dask-report.html").write_text("<html></html>")
    path = write_report(tmp_path, metrics=json.loads((tmp_path / "metrics.json").read_text()))
    assert path == str(tmp_path / "report.html")
    page = (tmp_path / "report.html").read_text()
    p = parse(page)
    # the floor plan is inside the page, byte for byte
    src = p.images[0]
    assert src.startswith("data:image/png;base64,")
    assert base64.b64decode(src.split(",", 1)[1]) == (tmp_path / "floorplan.png").read_bytes()
    assert "dask-report.html" in p.links and "metrics.json" in p.links
    assert all(not h.startswith(("http:", "https:", "/")) for h in p.links)  # relative links only
    assert "<link" not in page and "<script" not in page  # no external stylesheet or script
    stats = space_statistics(spaces, elements)
    st = rows(p.tables["space-stats"])
    header = p.tables["space-stats"][0]
    row = dict(zip(header[1:], st["0"]))
    assert num(row["area (m²)"]) == pytest.approx(stats["spaces"][0]["area_m2"])
    assert num(row["perimeter (m)"]) == pytest.approx(18.0)
    assert num(row["points"]) == 500 and num(row["wall"]) == 1 and num(row["window"]) == 1
    assert num(row["window/wall"]) == pytest.approx(1.2 / 12, abs=5e-4)
    with pytest.raises(FileNotFoundError):
        write_report(tmp_path / "nope", metrics=METRICS)


def test_provenance_is_shown():
    prov = {"package": "buildingparser", "version": "0.1.0", "git": {"commit": "ab" * 20, "dirty": True},
            "model": {"name": "default", "default": True, "path": "/m/default",
                      "sha256": {"default.npz": "f" * 64, "default.json": "e" * 64}},
            "settings": {"buildingparser": {"tiles.size": 20.0}, "run": {"crf": False}},
            "input": {"name": "scan<1>.laz", "size": 123456, "sha256": "d" * 64},
            "started": "2026-12-03T07:00:00+00:00", "ended": "2026-12-03T07:05:00+00:00",
            "cluster": {"kind": "dask distributed", "workers": 2}}
    page = render_report({**METRICS, "provenance": prov})
    t = rows(parse(page).tables["provenance"])
    assert t["package"] == ["buildingparser 0.1.0"] and t["git commit"] == ["ab" * 20 + " (uncommitted changes)"]
    assert t["model"] == ["default (shipped default)"] and t["model sha256: default.npz"] == ["f" * 64]
    assert t["input"] == ["scan<1>.laz, 123,456 bytes"] and t["input sha256"] == ["d" * 64]
    assert t["started"] == ["2026-12-03T07:00:00+00:00"] and t["ended"] == ["2026-12-03T07:05:00+00:00"]
    assert t["setting buildingparser.tiles.size"] == ["20.0"] and t["setting run: crf"] == ["false"]
    assert "scan&lt;1&gt;.laz" in page
    assert "No provenance recorded" in render_report(METRICS)


def test_a_path_that_is_not_utf8_is_shown_escaped(tmp_path):
    import os

    raw = os.fsdecode(b"/data/caf\xe9 scan/r\xc3\xa9sum\xff.laz")  # latin-1 bytes, then UTF-8, then a stray byte
    metrics = dict(METRICS, input=dict(METRICS["input"], path=raw))
    (tmp_path / "metrics.json").write_text(json.dumps(metrics))
    path = write_report(tmp_path, metrics=json.loads((tmp_path / "metrics.json").read_text()))
    page = open(path, encoding="utf-8").read()  # valid UTF-8
    assert "/data/caf\\xe9 scan/résum\\xff.laz" in page and "résum\\xff.laz" in page.split("<title>")[1]
