"""The settings loader: declarations, typed values, dataclasses from sections, the whole-tree check."""
from __future__ import annotations

import dataclasses
import pickle

import dask
import pytest

import tiles.config as tc
from tiles.config import setting, settings_fields, validate_settings
from tiles.errors import BuildingParserError, IncompleteStoreError, SettingsError, UserError
from tiles.settings_spec import Spec
from tiles.tasks import TaskFailures


@pytest.mark.parametrize("decl, value, typed", [
    ("float > 0", 3, 3.0), ("float > 0", "0.5", 0.5), ("float in [0, 1]", 1, 1.0), ("float", -2.5, -2.5),
    ("int >= 1", 2, 2), ("int >= 1", 2.0, 2), ("int >= 0", "7", 7), ("int in [0, 2]", 0, 0),
    ("bool", True, True), ("bool", "no", False), ("bool", "Yes", True), ("bool", 0, False),
    ("str | null", None, None), ("str", "tcp://h:8786", "tcp://h:8786"),
    ("one of auto, always, never", "never", "never"),
    ("classes", "door, window", ("door", "window")), ("classes", ["wall"], ("wall",)), ("classes", "", ()),
    ("names of no_local, no_color", "no_color", ("no_color",)),
    ("floats > 0", [0.02, 1], (0.02, 1.0)),
    ("classes -> int >= 0", {"wall": 4}, {"wall": 4}),
    ("duration", "20s", "20s"), ("duration", 5, 5),
    ("memory", "auto", "auto"), ("memory", "4GiB", "4GiB"), ("memory", 2**30, 2**30),
])
def test_a_good_value_comes_back_typed(decl, value, typed):
    got = Spec.parse(decl).check(value)
    assert got == typed and type(got) is type(typed)


@pytest.mark.parametrize("decl, value", [
    ("float > 0", 0), ("float > 0", -3), ("float >= 0", float("nan")), ("float", float("inf")), ("float", True),
    ("float", "fast"), ("float in (0, 0.5)", 0.5), ("float in [0, 1]", 1.01), ("float > 0", None),
    ("int >= 1", 2.5), ("int >= 1", 0), ("int >= 0", False), ("int in [0, 2]", 3),
    ("bool", "maybe"), ("bool", 2), ("str", 5), ("one of auto, always, never", "sometimes"),
    ("classes", "door,windoe"), ("classes", 3), ("names of no_local, no_color", "no_colour"),
    ("floats > 0", []), ("floats > 0", [0.1, -1]), ("floats > 0", 0.1),
    ("classes -> int >= 0", {"wal": 2}), ("classes -> int >= 0", {"wall": -1}), ("classes -> int >= 0", [1]),
    ("duration", "soon"), ("memory", "lots"), ("memory", -1),
])
def test_a_bad_value_is_refused_with_what_is_expected(decl, value):
    spec = Spec.parse(decl)
    with pytest.raises(ValueError) as err:
        spec.check(value)
    assert str(err.value) == spec.expected()


def test_expected_reads_as_words():
    assert Spec.parse("float > 0").expected() == "a number > 0"
    assert Spec.parse("int >= 1 | null").expected() == "an integer >= 1 or null"
    assert Spec.parse("float in (0, 0.5)").expected() == "a number in (0, 0.5)"
    assert Spec.parse("one of error, skip").expected() == "one of error, skip"
    assert Spec.parse("classes -> int >= 0").expected() == "a mapping of element class to an integer >= 0"
    with pytest.raises(ValueError):
        Spec.parse("number > 0")
    with pytest.raises(ValueError):
        Spec.parse("float about 3")


def test_setting_reads_the_tiles_defaults_typed():
    assert setting("tiles.size") == 10.0 and isinstance(setting("tiles.size"), float)
    assert setting("ingest.part-points") == 2_000_000 and setting("export.window") is None
    with dask.config.set({"buildingparser.tiles.size": "20"}):
        assert setting("tiles.size") == 20.0
    with dask.config.set({"buildingparser.tiles.size": -1}), pytest.raises(SettingsError) as err:
        setting("tiles.size")
    assert err.value.line() == "setting buildingparser.tiles.size = -1: must be a number > 0"
    with pytest.raises(KeyError):
        setting("tiles.colour")


@pytest.fixture
def toy_schema(monkeypatch):
    """A private registry with a toy section ``toy`` (the real one is left as it was)."""
    monkeypatch.setattr(tc, "SCHEMA", dict(tc.SCHEMA))
    monkeypatch.setattr(tc, "SCHEMA_DEFAULTS", dict(tc.SCHEMA_DEFAULTS))
    monkeypatch.setattr(tc, "ORDERED", list(tc.ORDERED))
    tc.declare({"toy": {"size": "float > 0", "count": "int >= 0", "name-of-it": "str | null",
                        "inner": {"flag": "bool", "lo": "float", "hi": "float"}, "extra": "int >= 0"}},
               defaults={"toy.extra": 7}, ordered=(("toy.inner.lo", "toy.inner.hi"),))
    with dask.config.set({"buildingparser.toy": {"size": 2, "count": 3, "name-of-it": None,
                                                  "inner": {"flag": "false", "lo": 0, "hi": 1}}}):
        yield


@dataclasses.dataclass(frozen=True)
class Inner:
    flag: bool = True
    lo: float = 0.0
    hi: float = 1.0


@dataclasses.dataclass(frozen=True)
class Toy:
    size: float = 1.0
    count: int = 0
    name_of_it: str = "default"
    inner: Inner = dataclasses.field(default_factory=Inner)
    undeclared: int = 5


def test_settings_fields_fill_a_dataclass_from_its_section(toy_schema):
    kw = settings_fields(Toy, "toy")
    # the null name keeps its default, the nested section becomes an Inner, the undeclared field is left out
    assert kw == {"size": 2.0, "count": 3, "inner": Inner(flag=False, lo=0.0, hi=1.0)}
    assert Toy(**kw) == Toy(size=2.0, count=3, inner=Inner(False, 0.0, 1.0))
    assert settings_fields(Toy, "toy", keys={"count": "extra"}) == {"count": 7}  # its declared default
    with dask.config.set({"buildingparser.toy.inner.flag": "sometimes"}), pytest.raises(SettingsError, match="flag"):
        settings_fields(Toy, "toy")


def test_validate_settings_refuses_typos_bad_values_sections_and_disorder(toy_schema):
    validate_settings()
    cases = [
        ({"buildingparser.toy.sise": 2},
         "unknown setting buildingparser.toy.sise (did you mean buildingparser.toy.size?)"),
        ({"buildingparser.toy.count": -1}, "setting buildingparser.toy.count = -1: must be an integer >= 0"),
        ({"buildingparser.toy.inner": 3}, "setting buildingparser.toy.inner = 3: must be a section of settings"),
        ({"buildingparser.toy.inner.lo": 2}, "setting buildingparser.toy.inner.lo = 2.0: must be <= "
                                             "buildingparser.toy.inner.hi (1.0)"),
        ({"buildingparser.nothing-like-it": 1}, "unknown setting buildingparser.nothing-like-it"),
    ]
    for values, message in cases:
        with dask.config.set(values), pytest.raises(SettingsError) as err:
            validate_settings()
        assert err.value.line().startswith(message), err.value.line()
        assert "\n" not in err.value.line()


def test_underscored_keys_of_environment_variables_are_the_dashed_ones(toy_schema):
    env = dask.config.collect_env({"DASK_BUILDINGPARSER__TOY__NAME_OF_IT": "5", "DASK_BUILDINGPARSER__TOY__COUNT": "2"})
    assert env == {"buildingparser": {"toy": {"name_of_it": 5, "count": 2}}}  # as dask reads them at import
    with dask.config.set(env), pytest.raises(SettingsError) as err:
        validate_settings()
    assert err.value.line() == "setting buildingparser.toy.name-of-it = 5: must be a string or null"
    with dask.config.set({"buildingparser": {"toy": {"name_of_it": "x", "count": 2}}}):
        validate_settings()


def test_one_base_exception_and_the_old_names():
    assert issubclass(UserError, BuildingParserError) and issubclass(TaskFailures, BuildingParserError)
    assert issubclass(SettingsError, UserError) and issubclass(IncompleteStoreError, UserError)
    err = SettingsError("buildingparser.crf.time-limit", -3, "a number > 0")
    back = pickle.loads(pickle.dumps(err))  # a task's error travels from a worker to the client
    assert type(back) is SettingsError and back.line() == err.line() == \
        "setting buildingparser.crf.time-limit = -3: must be a number > 0"
    assert pickle.loads(pickle.dumps(UserError("a.laz", "broken"))).line() == "a.laz: broken"


def test_non_default_settings_name_only_what_differs_from_the_defaults():
    from tiles.config import non_default_settings

    base = non_default_settings()
    assert "tiles.size" not in base
    with dask.config.set({"buildingparser.tiles.size": "20", "buildingparser.ingest.part-points": 2_000_000,
                          "buildingparser.export.window": 3}):
        got = non_default_settings()
    assert got == {**base, "tiles.size": 20.0, "export.window": 3}  # a default set again is no difference
