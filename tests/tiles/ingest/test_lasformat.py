"""tiles.ingest.lasformat: what a LAS point format holds, and the store's dimensions of it."""
from __future__ import annotations

import laspy
import numpy as np

from tiles.ingest.lasformat import bit_shift, choose_point_format, point_dimensions, subfields


def test_choose_point_format():
    assert choose_point_format(3, {"intensity", "red"}) == 3
    assert choose_point_format(1, {"intensity", "red", "gps_time"}) == 3
    assert choose_point_format(None, {"red"}) == 7
    assert choose_point_format(6, {"nir"}) == 8


def test_bit_fields_shift_to_their_lowest_bit():
    subs = subfields(6)
    packed, mask = subs["number_of_returns"]
    assert packed == "bit_fields" and mask == 0b11110000 and bit_shift(mask) == 4
    assert bit_shift(subs["return_number"][1]) == 0
    assert bit_shift(subs["edge_of_flight_line"][1]) == 7


def test_point_dimensions_name_every_field_and_unpack_bit_fields_and_arrays():
    pf = laspy.PointFormat(3)
    pf.add_extra_dimension(laspy.ExtraBytesParams("pair", "2int16", scales=np.array([0.5, 0.5]),
                                                  offsets=np.array([0.0, 0.0])))
    pf.add_extra_dimension(laspy.ExtraBytesParams("gt_class", "uint8"))
    dims, extract = point_dimensions(pf)
    by_name = {d.name: d for d in dims}
    assert [d.name for d in dims[:3]] == ["x", "y", "z"]
    # a LAS classification never takes the pipeline's result name
    assert by_name["source_classification"].las == {"name": "classification"}
    assert dict(extract)["return_number"] == ("bits", "bit_fields", 0b00000111)
    assert by_name["return_number"].dtype == "uint8"
    assert dict(extract)["pair_1"] == ("component", "pair", 1)
    assert by_name["pair_1"].las["component"] == 1 and by_name["pair_1"].las["scales"] == [0.5, 0.5]
    assert by_name["gt_class"].kind == "ground_truth"
    assert [n for n, _ in extract] == [d.name for d in dims[3:]]
