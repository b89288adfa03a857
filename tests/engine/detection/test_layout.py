"""The feature layout: its groups' columns, round trips through JSON, layouts written by older versions."""
from __future__ import annotations

from engine.detection.layout import FeatureLayout


def test_layout_colour_mode_round_trips_and_old_models_read_as_raw():
    lay = FeatureLayout(k=2)
    assert FeatureLayout.from_json(lay.to_json()).colour == "space-median"
    old = {k: v for k, v in lay.to_json().items() if k != "colour"}  # written before the mode existed
    assert FeatureLayout.from_json(old).colour == "none"


def test_layouts_written_before_the_context_block_load_without_it():
    d = FeatureLayout().to_json()
    old = FeatureLayout.from_json({k: v for k, v in d.items() if k not in ("context", "size")})
    assert not old.context and old.size == FeatureLayout().size - 15 and "context_fill" not in old.spans
    assert old.local_end == old.size
    assert FeatureLayout.from_json(d).context
    assert not FeatureLayout(k=2).without(("context_color",)).mask[-9:].any()
