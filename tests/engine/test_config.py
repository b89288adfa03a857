"""Every buildingparser.* setting is declared, its default passes, and a bad one stops the CLI before any work."""
from __future__ import annotations

import glob
import os
import pathlib
import subprocess
import sys

import dask
import pytest
import yaml

import engine.config
import engine.pipeline.cluster as cluster
from engine.cli import main
from engine.crf.model import CRFSettings
from engine.detection.reveal import RevealSettings
from engine.detection.settings import DetectionSettings
from engine.spaces.settings import SpaceSettings
from engine.training.settings import TrainSettings
from tiles.config import SCHEMA, SCHEMA_DEFAULTS, setting, validate_settings
from tiles.errors import SettingsError

ROOT = pathlib.Path(__file__).resolve().parents[2]
YAML_FILES = sorted([str(ROOT / "tiles" / "tiles.yaml"), *glob.glob(str(ROOT / "engine" / "*" / "*.yaml"))])


def _leaves(tree, prefix=""):
    for k, v in tree.items():
        key = prefix + k
        if isinstance(v, dict) and key not in SCHEMA:
            yield from _leaves(v, key + ".")
        else:
            yield key, v


def _yaml_defaults() -> dict:
    out = {}
    for path in YAML_FILES:
        with open(path) as f:
            out.update(_leaves((yaml.safe_load(f) or {}).get("buildingparser", {})))
    return out


def test_every_yaml_default_is_declared_and_passes_its_declaration():
    defaults = _yaml_defaults()
    assert len(YAML_FILES) == 8 and len(defaults) > 150
    undeclared = sorted(set(defaults) - set(SCHEMA))
    assert not undeclared, f"keys in the YAML files without a declaration: {undeclared}"
    for key, value in defaults.items():
        SCHEMA[key].check(value)  # raises ValueError on a default its own declaration refuses
    # a declared key is in some YAML file, has a declared default, or is a dataclass field no YAML sets
    unset = set(SCHEMA) - set(defaults) - set(SCHEMA_DEFAULTS)
    assert unset == {"spaces.slabs.empty-fraction", "spaces.slabs.empty-smooth"}
    validate_settings()  # the registered defaults as dask.config holds them


def test_the_settings_classes_are_built_from_the_typed_settings():
    overrides = {"buildingparser.detection.refine": "no", "buildingparser.detection.reveal-classes": ["door", "window"],
                 "buildingparser.detection.train.rounds": "2", "buildingparser.detection.train.atom-weights": "off",
                 "buildingparser.detection.k": 3.0, "buildingparser.crf.time-limit": "12",
                 "buildingparser.spaces.walls.pass-widths": [0.02, 0.04], "buildingparser.spaces.yaw": 10}
    with dask.config.set(overrides):
        validate_settings()
        det, reveal, train = DetectionSettings.from_config(), RevealSettings.from_config(), TrainSettings.from_config()
        crf, spaces = CRFSettings.from_config(), SpaceSettings.from_config()
    assert det.refine is False and reveal.classes == ("door", "window")
    assert (train.rounds, train.atom_weights, train.k) == (2, False, 3) and type(train.k) is int
    assert crf.time_limit == 12.0 and type(crf.time_limit) is float
    assert spaces.walls.pass_widths == (0.02, 0.04) and spaces.yaw == 10.0
    assert spaces.slabs.pass_widths == (0.04, 0.08, 0.16, 0.32)  # slabs keep their own section
    assert setting("crf.k-per-class") == {} and engine.config.setting is setting


@pytest.fixture
def no_cluster(monkeypatch):
    """Starting a cluster fails the test: a bad setting must stop the command before."""
    def refuse(*args, **kwargs):
        raise AssertionError("a cluster was started")

    monkeypatch.setattr(cluster, "LocalCluster", refuse)
    monkeypatch.setattr(cluster, "Client", refuse)


# one bad value of each kind of declaration
BAD = [
    ("crf.time-limit", -3, "must be a number > 0"),
    ("detection.stride", 1.5, "must be a number in (0, 1]"),
    ("crf.max-nodes-per-class", 2.5, "must be an integer >= 1"),
    ("crf.linearization-level", 3, "must be an integer in [0, 2]"),
    ("detection.refine", "maybe", "must be true or false"),
    ("progress", "sometimes", "must be one of auto, always, never"),
    ("detection.reveal-classes", "door,windoe", "must be comma-separated element classes"),
    ("detection.train.select-groups", "no_colour", "must be comma-separated names from no_local"),
    ("spaces.walls.pass-widths", [0.02, -1], "must be a non-empty list of numbers > 0"),
    ("crf.k-per-class", {"wal": 2}, "must be a mapping of element class to an integer >= 0"),
    ("connect-timeout", "soon", "must be a duration"),
    ("memory-limit", "lots", "must be auto, a size"),
    ("scheduler", 5, "must be a string or null"),
    ("export.window", 0, "must be an integer >= 1 or null"),
    ("spaces.yaw", "north", "must be a number or null"),
    ("spaces.walls", 3, "must be a section of settings"),
    ("detection.train.neg-iou", 0.7, "must be <= buildingparser.detection.train.pos-iou (0.6)"),
]


@pytest.mark.parametrize("key, value, expected", BAD, ids=[b[0] for b in BAD])
def test_a_bad_setting_stops_the_command_line_in_one_line(key, value, expected, tmp_path, capsys, no_cluster):
    with dask.config.set({f"buildingparser.{key}": value}):
        rc = main(["run", str(tmp_path / "missing.laz"), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert err.startswith(f"buildingparser: error: setting buildingparser.{key} = ") and expected in err, err
    assert "\n" not in err and "missing.laz" not in err and "Traceback" not in err


def test_an_unknown_setting_is_refused_with_the_closest_name(tmp_path, capsys, no_cluster):
    with dask.config.set({"buildingparser.crf.time-limt": 3}):
        rc = main(["run", str(tmp_path / "missing.laz"), "--out", str(tmp_path / "out")])
    assert rc == 2
    assert capsys.readouterr().err.strip() == ("buildingparser: error: unknown setting buildingparser.crf.time-limt "
                                               "(did you mean buildingparser.crf.time-limit?)")


def test_good_settings_reach_the_command(tmp_path, capsys, no_cluster):
    """Valid settings pass the check: the command runs and starts its cluster (refused here)."""
    (tmp_path / "in.laz").write_bytes(b"")  # the input is checked before the cluster: it must exist
    with dask.config.set({"buildingparser.crf.time-limit": 3}), pytest.raises(AssertionError, match="cluster"):
        main(["run", str(tmp_path / "in.laz"), "--out", str(tmp_path / "out")])


def test_the_python_run_checks_the_settings_first(tmp_path):
    from engine.pipeline.run import run

    with dask.config.set({"buildingparser.space-update.coverage": 0}), pytest.raises(SettingsError) as err:
        run(str(tmp_path / "missing.laz"), str(tmp_path / "out"))
    assert err.value.line() == "setting buildingparser.space-update.coverage = 0: must be a number in (0, 1]"
    assert not (tmp_path / "out").exists()


def test_an_environment_variable_is_checked_too(tmp_path):
    env = {k: v for k, v in os.environ.items() if not k.startswith("DASK_BUILDINGPARSER")}
    env["DASK_BUILDINGPARSER__CRF__TIME_LIMIT"] = "-3"
    proc = subprocess.run([sys.executable, "-m", "engine.cli", "run", str(tmp_path / "missing.laz"), "--out",
                           str(tmp_path / "out")], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.strip() == ("buildingparser: error: setting buildingparser.crf.time-limit = -3: "
                                   "must be a number > 0")
