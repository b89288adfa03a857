"""``building.ifc``: the parse as a building model (IFC4, written with ifcopenshell).

Read from the run's outputs (``spaces.geojson``, ``elements.json``), so that it
can be written again for any run folder (``buildingparser ifc OUT``) or an
edited one:

* project (metres), site, building, one ``IfcBuildingStorey`` per storey of the
  parse (its elevation: the lowest floor of its spaces);
* one ``IfcSpace`` per space: its footprint (outer ring; the largest part of a
  multi-part footprint) extruded from its floor to its ceiling, named
  ``Space <id>``, with ``Qto_SpaceBaseQuantities`` (net floor area, height,
  gross volume) and ``BuildingParser_Space`` (every property of its
  ``spaces.geojson`` feature: id, points, statistics, the daylight figures of
  :mod:`engine.outputs.daylight`; lists as comma-separated text);
* one product per detected element, its box as an extruded rectangle placed
  and turned (yaw) where the element is: wall ``IfcWall``, floor ``IfcSlab``
  (FLOOR), ceiling ``IfcCovering`` (CEILING), beam ``IfcBeam``, column
  ``IfcColumn``, door ``IfcDoor``, window ``IfcWindow``, table, chair, sofa
  and bookcase ``IfcFurniture`` (TABLE, CHAIR, SOFA, SHELF), board
  ``IfcFurniture`` (USERDEFINED, "board"); clutter is not a building element
  and is left out.  Each is contained in its storey
  (``IfcRelContainedInSpatialStructure``) and referenced by its space
  (``IfcRelReferencedInSpatialStructure``), with ``BuildingParser_Element``
  (element id, class, score, space);
* coordinates: the model's origin is a round point near the building's lower
  corner (``LOCAL_ROUNDING`` metres), so that viewers keep their precision.
  With a CRS (``crs`` or ``crs_wkt`` of ``spaces.geojson``), the origin is the
  ``IfcMapConversion``'s eastings/northings/height into an ``IfcProjectedCRS``;
  without one the site is placed at the origin, so that world coordinates are
  the placements' sum either way.

The file is written to a temporary name and renamed.
"""
from __future__ import annotations

import math
import os
from typing import Any

import numpy as np

IFC_FILE = "building.ifc"
LOCAL_ROUNDING = 100.0
#: Element class -> (IFC class, predefined type, object type).
IFC_CLASSES = {
    "wall": ("IfcWall", "NOTDEFINED", None), "floor": ("IfcSlab", "FLOOR", None),
    "ceiling": ("IfcCovering", "CEILING", None), "beam": ("IfcBeam", "BEAM", None),
    "column": ("IfcColumn", "COLUMN", None), "door": ("IfcDoor", "DOOR", None),
    "window": ("IfcWindow", "WINDOW", None), "table": ("IfcFurniture", "TABLE", None),
    "chair": ("IfcFurniture", "CHAIR", None), "sofa": ("IfcFurniture", "SOFA", None),
    "bookcase": ("IfcFurniture", "SHELF", None), "board": ("IfcFurniture", "USERDEFINED", "board"),
}


def _api():
    import ifcopenshell
    import ifcopenshell.api
    import ifcopenshell.api.aggregate
    import ifcopenshell.api.context
    import ifcopenshell.api.project
    import ifcopenshell.api.pset
    import ifcopenshell.api.root
    import ifcopenshell.api.spatial
    import ifcopenshell.api.unit  # noqa: F401 (the API's submodules are imported one by one)

    return ifcopenshell, ifcopenshell.api


def crs_of_layer(layer: dict[str, Any]) -> dict[str, Any] | None:
    """The CRS of a spaces layer as ``{"name": "EPSG:n" or a name, "wkt": ...}``, or None."""
    wkt = layer.get("crs_wkt")
    name = ((layer.get("crs") or {}).get("properties") or {}).get("name")
    if not wkt and not name:
        return None
    try:
        from pyproj import CRS

        crs = CRS.from_user_input(wkt or name)
        epsg = crs.to_epsg()
        return {"name": f"EPSG:{epsg}" if epsg else crs.name, "wkt": crs.to_wkt(), "projected": crs.is_projected}
    except Exception:  # noqa: BLE001 - pyproj absent or a CRS it cannot read: keep the text
        return {"name": name or "unknown", "wkt": wkt, "projected": True}


def _origin(layer: dict[str, Any], elements: list[dict[str, Any]]) -> np.ndarray:
    pts = [np.asarray(e["center"], float) for e in elements]
    for f in layer.get("features", []):
        g = f.get("geometry") or {}
        for ring in _rings(g):
            a = np.asarray(ring, float)[:, :2]
            z = float(f["properties"].get("z_min", 0.0))
            pts.append(np.r_[a.min(axis=0), z])
    if not pts:
        return np.zeros(3)
    lo = np.min(pts, axis=0)
    return np.floor(lo / LOCAL_ROUNDING) * LOCAL_ROUNDING * np.array([1.0, 1.0, 0.0])


def _rings(g: dict[str, Any]) -> list[list[list[float]]]:
    if g.get("type") == "Polygon" and g.get("coordinates"):
        return [g["coordinates"][0]]
    if g.get("type") == "MultiPolygon":
        return [p[0] for p in g["coordinates"] if p]
    return []


class _Writer:
    """The model being written: its contexts, storeys and the placement helpers."""

    def __init__(self, origin: np.ndarray, crs: dict[str, Any] | None, name: str):
        ifcopenshell, api = _api()
        self.api = api
        self.m = api.project.create_file(version="IFC4")
        self.origin = origin
        self.project = api.root.create_entity(self.m, ifc_class="IfcProject", name=name)
        length = api.unit.add_si_unit(self.m, unit_type="LENGTHUNIT")
        area = api.unit.add_si_unit(self.m, unit_type="AREAUNIT")
        volume = api.unit.add_si_unit(self.m, unit_type="VOLUMEUNIT")
        api.unit.assign_unit(self.m, units=[length, area, volume])
        model = api.context.add_context(self.m, context_type="Model")
        self.body = api.context.add_context(self.m, context_type="Model", context_identifier="Body",
                                            target_view="MODEL_VIEW", parent=model)
        self.site = api.root.create_entity(self.m, ifc_class="IfcSite", name="Site")
        self.building = api.root.create_entity(self.m, ifc_class="IfcBuilding", name="Building")
        api.aggregate.assign_object(self.m, relating_object=self.project, products=[self.site])
        api.aggregate.assign_object(self.m, relating_object=self.site, products=[self.building])
        site_at = np.zeros(3) if crs else origin
        self.site.ObjectPlacement = self.placement(site_at, 0.0, None)
        self.building.ObjectPlacement = self.placement(np.zeros(3), 0.0, self.site.ObjectPlacement)
        if crs:
            self._georeference(crs)

    def _georeference(self, crs: dict[str, Any]) -> None:
        m = self.m
        context = next(c for c in m.by_type("IfcGeometricRepresentationContext") if not c.is_a("IfcGeometricRepresentationSubContext"))
        target = m.createIfcProjectedCRS(Name=crs["name"], Description=(crs.get("wkt") or "")[:255] or None)
        m.createIfcMapConversion(SourceCRS=context, TargetCRS=target, Eastings=float(self.origin[0]),
                                 Northings=float(self.origin[1]), OrthogonalHeight=float(self.origin[2]))

    def placement(self, at: np.ndarray, yaw: float, relative_to) -> Any:
        m = self.m
        axis = m.createIfcAxis2Placement3D(
            m.createIfcCartesianPoint([float(v) for v in at]), m.createIfcDirection([0.0, 0.0, 1.0]),
            m.createIfcDirection([math.cos(yaw), math.sin(yaw), 0.0]))
        return m.createIfcLocalPlacement(relative_to, axis)

    def extrusion(self, profile, depth: float) -> Any:
        m = self.m
        solid = m.createIfcExtrudedAreaSolid(profile, m.createIfcAxis2Placement3D(
            m.createIfcCartesianPoint([0.0, 0.0, 0.0])), m.createIfcDirection([0.0, 0.0, 1.0]), max(float(depth), 1e-3))
        rep = m.createIfcShapeRepresentation(self.body, "Body", "SweptSolid", [solid])
        return m.createIfcProductDefinitionShape(None, None, [rep])


def _storey_levels(layer: dict[str, Any]) -> dict[int, float]:
    levels: dict[int, float] = {}
    for f in layer.get("features", []):
        p = f["properties"]
        s = int(p.get("floor", 0))
        levels[s] = min(levels.get(s, math.inf), float(p.get("z_min", 0.0)))
    return levels or {0: 0.0}


def _add_space(w: _Writer, f: dict[str, Any], storey) -> Any:
    api, m, p = w.api, w.m, f["properties"]
    rings = _rings(f.get("geometry") or {})
    space = api.root.create_entity(m, ifc_class="IfcSpace", name=f"Space {p['id']}", predefined_type="INTERNAL")
    z0, z1 = float(p.get("z_min", 0.0)), float(p.get("z_max", 0.0))
    space.ObjectPlacement = w.placement(np.array([0.0, 0.0, z0 - float(storey.Elevation)]), 0.0,
                                        storey.ObjectPlacement)
    if rings:
        from shapely.geometry import Polygon

        ring = max(rings, key=lambda r: Polygon(r).area)
        local = np.asarray(ring, float)[:, :2] - w.origin[:2]
        if np.allclose(local[0], local[-1]):
            local = local[:-1]
        curve = m.createIfcPolyline([m.createIfcCartesianPoint([float(x), float(y)]) for x, y in local]
                                    + [m.createIfcCartesianPoint([float(local[0][0]), float(local[0][1])])])
        space.Representation = w.extrusion(m.createIfcArbitraryClosedProfileDef("AREA", None, curve), z1 - z0)
    area = float(p.get("area_m2", 0.0))
    qto = api.pset.add_qto(m, product=space, name="Qto_SpaceBaseQuantities")
    api.pset.edit_qto(m, qto=qto, properties={"NetFloorArea": area, "Height": z1 - z0,
                                              "GrossVolume": area * (z1 - z0)})
    props = {k: v for k, v in p.items() if isinstance(v, (int, float, str, bool)) and v is not None}
    props.update({k: ", ".join(str(x) for x in v) for k, v in p.items() if isinstance(v, list) and v})
    pset = api.pset.add_pset(m, product=space, name="BuildingParser_Space")
    api.pset.edit_pset(m, pset=pset, properties=props)
    return space


def _add_element(w: _Writer, e: dict[str, Any], storey) -> Any | None:
    spec = IFC_CLASSES.get(e["class"])
    if spec is None:
        return None
    api, m = w.api, w.m
    cls, predefined, object_type = spec
    product = api.root.create_entity(m, ifc_class=cls, name=f"{e['class']} {e['element_id']}",
                                     predefined_type=predefined)
    if object_type:
        product.ObjectType = object_type
    c, s = np.asarray(e["center"], float), np.asarray(e["size"], float)
    bottom = c - w.origin - np.array([0.0, 0.0, s[2] / 2 + float(storey.Elevation)])
    product.ObjectPlacement = w.placement(bottom, float(e.get("yaw", 0.0)), storey.ObjectPlacement)
    profile = m.createIfcRectangleProfileDef("AREA", None, m.createIfcAxis2Placement2D(
        m.createIfcCartesianPoint([0.0, 0.0])), max(float(s[0]), 1e-3), max(float(s[1]), 1e-3))
    product.Representation = w.extrusion(profile, s[2])
    pset = api.pset.add_pset(m, product=product, name="BuildingParser_Element")
    api.pset.edit_pset(m, pset=pset, properties={"ElementId": int(e["element_id"]), "Class": e["class"],
                                                 "Score": float(e["score"]), "SpaceId": int(e["space_id"])})
    return product


def build_model(layer: dict[str, Any], elements: list[dict[str, Any]], *, name: str = "buildingparser") -> Any:
    """The IFC4 model (an ``ifcopenshell.file``) of a spaces layer and its elements."""
    crs = crs_of_layer(layer)
    w = _Writer(_origin(layer, elements), crs, name)
    api, m = w.api, w.m
    storeys = {}
    for s, z in sorted(_storey_levels(layer).items()):
        st = api.root.create_entity(m, ifc_class="IfcBuildingStorey", name=f"Storey {s}")
        st.Elevation = float(z - w.origin[2])
        st.ObjectPlacement = w.placement(np.array([0.0, 0.0, st.Elevation]), 0.0, w.building.ObjectPlacement)
        storeys[s] = st
    api.aggregate.assign_object(m, relating_object=w.building, products=list(storeys.values()))
    spaces, floor_of = {}, {}
    for f in layer.get("features", []):
        sid, s = int(f["properties"]["id"]), int(f["properties"].get("floor", 0))
        spaces[sid], floor_of[sid] = _add_space(w, f, storeys[s]), s
    for s, st in storeys.items():
        mine = [spaces[i] for i in spaces if floor_of[i] == s]
        if mine:
            api.aggregate.assign_object(m, relating_object=st, products=mine)
    first = min(storeys)
    by_space: dict[int, list[Any]] = {}
    by_storey: dict[int, list[Any]] = {}
    for e in elements:
        s = floor_of.get(int(e.get("space_id", -1)), first)
        product = _add_element(w, e, storeys[s])
        if product is not None:
            by_storey.setdefault(s, []).append(product)
            if int(e.get("space_id", -1)) in spaces:
                by_space.setdefault(int(e["space_id"]), []).append(product)
    for s, products in by_storey.items():
        api.spatial.assign_container(m, products=products, relating_structure=storeys[s])
    for sid, products in by_space.items():
        api.spatial.reference_structure(m, products=products, relating_structure=spaces[sid])
    return m


def write_ifc(folder: str, *, path: str | None = None) -> str:
    """Write ``building.ifc`` for the run folder ``folder`` (from its spaces.geojson and elements.json)."""
    from engine.outputs.runfolder import read_run_outputs

    layer, elements = read_run_outputs(folder)
    model = build_model(layer, elements, name=os.path.basename(os.path.normpath(folder)) or "buildingparser")
    path = path or os.path.join(folder, IFC_FILE)
    tmp = path + ".tmp.ifc"
    model.write(tmp)
    os.replace(tmp, path)
    return path
