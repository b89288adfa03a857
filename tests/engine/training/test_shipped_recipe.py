"""The shipped models were trained by ``make model``'s recipe: their provenance names the Makefile's buildings."""
from __future__ import annotations

import json
import os
import re

import pytest

from engine.detection.model import default_model_path
from engine.detection.modelchoice import colour_free_model_path
from engine.synth.hard.hardness import NAMES

MAKEFILE = os.path.join(os.path.dirname(__file__), "..", "..", "..", "Makefile")


def _makefile() -> str:
    if not os.path.exists(MAKEFILE):
        pytest.skip(f"{MAKEFILE} is absent (an installed package, not a checkout)")
    with open(MAKEFILE) as f:
        return f.read()


def _variables() -> dict[str, str]:
    return dict(re.findall(r"^([A-Z_]+) := (.*)$", _makefile(), flags=re.M))


def _synthetic(model: str) -> dict:
    """The generated buildings the recipe's ``train ... --model engine/models/<model>`` asks for."""
    n, seed, area = re.search(r"--synthetic (\d+) --seed (\d+) --area (\d+) [^\n]*--model engine/models/" + model,
                              _makefile()).groups()
    return {"buildings": int(n), "first_seed": int(seed), "area_m2": float(area)}


def _provenance(stem: str) -> dict:
    with open(stem + ".json") as f:
        return json.load(f)["provenance"]


def test_the_default_model_is_trained_on_the_recipes_clean_buildings():
    v = _variables()
    data = v["MODEL_DATA"]
    prov = _provenance(default_model_path())
    stores = [d for d in prov["data"] if not d.startswith("synthetic")]
    assert stores == [f"{data}/b{s}.zarr" for s in v["MODEL_SEEDS"].split()]
    assert prov["synthetic"] == _synthetic("default")


def test_the_colour_free_model_is_trained_on_the_clean_and_the_hard_buildings():
    v = _variables()
    data = v["MODEL_DATA"]
    prov = _provenance(colour_free_model_path())
    stores = [d for d in prov["data"] if not d.startswith("synthetic")]
    hard = v["HARD_SEEDS"].split()
    assert hard, "the colour-free model's recipe has hard buildings"
    assert stores == [f"{data}/b{s}.zarr" for s in v["MODEL_SEEDS"].split()] + [f"{data}/h{s}.zarr" for s in hard]
    assert prov["ablation"] == "no_color"
    assert prov["synthetic"] == _synthetic("nocolour")
    # the difficulties are the appearance ones: none that turns an element out of the building's axes
    difficulties = v["HARD_TRAINING"].split(",")
    assert not {"wing", "oblique", "stairs"} & set(difficulties)
    assert set(difficulties) <= set(NAMES)
