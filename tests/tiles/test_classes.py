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
