"""Class names and codes; element class lists of settings."""
from __future__ import annotations

import pytest

from tiles.classes import CLUTTER, class_code, element_class_list


def test_element_class_lists_from_strings_and_sequences():
    assert element_class_list(" door, column ,", "x") == ("door", "column")
    assert element_class_list(("wall",), "x") == ("wall",)
    assert element_class_list(None, "x") == ()
    with pytest.raises(ValueError, match="solid-classes: unknown element class\\(es\\) clutter"):
        element_class_list("column,clutter", "solid-classes")  # clutter is no element


def test_class_codes():
    assert class_code(" Door ") == 6 and class_code("stairs") == CLUTTER


def test_las_lookup_names_64_to_76_and_fits_the_vlr():
    from tiles.classes import LAS_CLASS_OFFSET, las_class_lookup

    got = las_class_lookup()
    assert LAS_CLASS_OFFSET == 64 and sorted(got) == list(range(64, 77))
    assert got[64] == "ceiling" and got[66] == "wall" and got[76] == "clutter"
    assert all(len(n.encode("ascii")) <= 15 for n in got.values())
