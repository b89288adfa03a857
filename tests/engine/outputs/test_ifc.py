"""building.ifc: schema-valid IFC4 with one IfcSpace per space and one product per element, where they are."""
from __future__ import annotations

import json

import numpy as np
import pytest

ifcopenshell = pytest.importorskip("ifcopenshell")

from engine.cli import main  # noqa: E402
from engine.outputs.ifc import IFC_CLASSES, build_model, write_ifc  # noqa: E402


def _layer(crs=None):
    def room(i, x0, floor, z0):
        ring = [[x0, 0.0], [x0 + 5, 0.0], [x0 + 5, 4.0], [x0, 4.0], [x0, 0.0]]
        return {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [ring]},
                "properties": {"id": i, "floor": floor, "area_m2": 20.0, "z_min": z0, "z_max": z0 + 2.8,
                               "point_count": 1000}}

    off = np.array([500_000.0, 4_100_000.0])
    feats = [room(0, 0.0, 0, 0.0), room(1, 5.0, 0, 0.0), room(2, 0.0, 1, 3.2)]
    for f in feats:
        f["geometry"]["coordinates"][0] = (np.asarray(f["geometry"]["coordinates"][0]) + off).tolist()
    layer = {"type": "FeatureCollection", "features": feats}
    if crs:
        layer["crs"] = {"type": "name", "properties": {"name": crs}}
    return layer, off


def _elements(off):
    def box(i, cls, space, c, size, yaw=0.0):
        return {"element_id": i, "class": cls, "class_code": 0, "score": 0.5 + i / 10, "space_id": space,
                "center": [c[0] + off[0], c[1] + off[1], c[2]], "size": size, "yaw": yaw}

    return [box(0, "wall", 0, [5.0, 2.0, 1.4], [0.15, 4.0, 2.8]), box(1, "floor", 0, [2.5, 2.0, 0.0], [5, 4, 0.02]),
            box(2, "ceiling", 1, [7.5, 2.0, 2.8], [5, 4, 0.02]), box(3, "door", 1, [5.0, 1.0, 1.05], [0.1, 0.9, 2.1]),
            box(4, "window", 2, [2.5, 0.0, 4.7], [1.2, 0.1, 1.2]), box(5, "table", 0, [2.0, 2.0, 0.4], [1.2, 0.8, 0.8], 0.5),
            box(6, "board", 1, [7.0, 3.9, 1.5], [1.8, 0.05, 1.2]), box(7, "clutter", 1, [6, 1, 0.2], [0.3, 0.3, 0.4]),
            box(8, "column", 2, [0.5, 0.5, 4.6], [0.3, 0.3, 2.8])]


def _world_bottom(product, model):
    import ifcopenshell.util.placement as up

    m = up.get_local_placement(product.ObjectPlacement)
    conv = model.by_type("IfcMapConversion")
    shift = np.array([conv[0].Eastings, conv[0].Northings, conv[0].OrthogonalHeight or 0.0]) if conv else 0.0
    return m[:3, 3] + shift, np.arctan2(m[1, 0], m[0, 0])


@pytest.mark.parametrize("crs", [None, "urn:ogc:def:crs:EPSG::32633"])
def test_model_is_valid_and_holds_every_space_and_element_where_it_is(tmp_path, crs):
    import ifcopenshell.validate

    layer, off = _layer(crs)
    elements = _elements(off)
    (tmp_path / "spaces.geojson").write_text(json.dumps(layer))
    (tmp_path / "elements.json").write_text(json.dumps(elements))
    path = write_ifc(str(tmp_path))
    model = ifcopenshell.open(path)
    log = ifcopenshell.validate.json_logger()
    ifcopenshell.validate.validate(model, log, express_rules=True)
    assert log.statements == []
    assert len(model.by_type("IfcSpace")) == 3 and len(model.by_type("IfcBuildingStorey")) == 2
    products = {p.Name: p for p in model.by_type("IfcElement")}
    assert len(products) == len(elements) - 1  # clutter is no building element
    for e in elements:
        if e["class"] == "clutter":
            continue
        p = products[f"{e['class']} {e['element_id']}"]
        assert p.is_a(IFC_CLASSES[e["class"]][0])
        at, yaw = _world_bottom(p, model)
        np.testing.assert_allclose(at, np.r_[e["center"][:2], e["center"][2] - e["size"][2] / 2], atol=1e-6)
        assert yaw == pytest.approx(e["yaw"])
        space = [r.RelatingStructure.Name for r in p.ReferencedInStructures]
        storey = [r.RelatingStructure.Name for r in p.ContainedInStructure]
        assert space == [f"Space {e['space_id']}"] and storey == [f"Storey {1 if e['space_id'] == 2 else 0}"]
    if crs:
        (conv,) = model.by_type("IfcMapConversion")
        assert conv.TargetCRS.Name == "EPSG:32633" and conv.Eastings == 500_000.0
    else:
        assert not model.by_type("IfcMapConversion")
    # reopened, the same counts
    again = ifcopenshell.open(path)
    assert {c: len(again.by_type(c)) for c in ("IfcSpace", "IfcWall", "IfcFurniture")} == \
        {"IfcSpace": 3, "IfcWall": 1, "IfcFurniture": 2}


def test_space_quantities_and_cli(tmp_path, capsys):
    import ifcopenshell.util.element as ue

    layer, off = _layer()
    model = build_model(layer, _elements(off))
    space = next(s for s in model.by_type("IfcSpace") if s.Name == "Space 0")
    q = ue.get_psets(space)["Qto_SpaceBaseQuantities"]
    assert q["NetFloorArea"] == pytest.approx(20.0) and q["GrossVolume"] == pytest.approx(56.0)
    (tmp_path / "spaces.geojson").write_text(json.dumps(layer))
    (tmp_path / "elements.json").write_text(json.dumps(_elements(off)))
    assert main(["ifc", str(tmp_path), "--validate"]) == 0
    assert (tmp_path / "building.ifc").is_file()
    assert main(["ifc", str(tmp_path / "nothing")]) == 2
    assert "not a finished run folder" in capsys.readouterr().err
