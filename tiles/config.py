"""The ``buildingparser.*`` settings: their defaults, their schema, and the one loader that reads them.

Override a setting like any dask setting: ``dask.config.set({"buildingparser.tiles.size": 20})``,
a YAML file in ``~/.config/dask/``, or ``DASK_BUILDINGPARSER__TILES__SIZE=20``.  Defaults live in
YAML files (``tiles/tiles.yaml`` here, ``engine/*/*.yaml`` for the engine); every key has a declared
type and range (:func:`declare`; the declarations: :class:`tiles.settings_spec.Spec`), and every read
goes through :func:`setting` (one key) or :func:`settings_fields` (a settings dataclass from a section),
which return the validated, typed value.  :func:`validate_settings` checks the whole ``buildingparser``
tree before any work starts: an unknown key or a bad value is one :class:`tiles.errors.SettingsError`
line naming the key, the value and what is expected.  See ``docs/design/settings.md``.

The environment of the dask worker processes (glibc's memory settings) is set here too.
"""
from __future__ import annotations

import dataclasses
import difflib
import os
from collections.abc import Iterator, Mapping
from typing import Any

import dask.config
import yaml

from tiles.errors import SettingsError
from tiles.settings_spec import Spec

_FILE = os.path.join(os.path.dirname(__file__), "tiles.yaml")
ROOT = "buildingparser"
_ABSENT = object()


def register() -> None:
    """Merge this package's defaults under the user's settings (idempotent).

    Besides ``buildingparser.*``, ``tiles.yaml`` sets the environment of dask's
    worker processes (``distributed.nanny.pre-spawn-environ``): distributed's own
    defaults are registered first so that these replace them (the defaults
    registered last win; a user's setting wins over both).
    """
    import distributed.config  # noqa: F401 - distributed's defaults before ours

    with open(_FILE) as f:
        defaults = yaml.safe_load(f)
    dask.config.update_defaults(defaults)


# -- the schema ------------------------------------------------------------------------------------------

#: Every declared key (relative to ``buildingparser``, with dashes) and what its value must be.
SCHEMA: dict[str, Spec] = {}
#: Defaults of declared keys that no YAML file sets.
SCHEMA_DEFAULTS: dict[str, Any] = {}
#: Pairs of keys whose values must be in order (``lo <= hi``).
ORDERED: list[tuple[str, str]] = []


def declare(tree: Mapping[str, Any], defaults: Mapping[str, Any] | None = None,
            ordered: tuple[tuple[str, str], ...] = ()) -> None:
    """Declare settings: ``tree`` mirrors a YAML file under ``buildingparser`` with declarations as leaves.

    Parameters
    ----------
    tree
        ``{"crf": {"k": "int >= 0", "ssvm": {...}}}``: a string is a key's declaration (see
        :class:`Spec`), a mapping is a section.
    defaults
        Values of declared keys that no YAML file sets (dotted keys).
    ordered
        Pairs of dotted keys whose values must satisfy ``lo <= hi``.
    """
    for key, decl in _walk_declarations(tree, ""):
        SCHEMA[key] = Spec.parse(decl)
    SCHEMA_DEFAULTS.update(defaults or {})
    ORDERED.extend(p for p in ordered if p not in ORDERED)


def _walk_declarations(tree: Mapping[str, Any], prefix: str) -> Iterator[tuple[str, str]]:
    for k, v in tree.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping):
            yield from _walk_declarations(v, key + ".")
        else:
            yield key, v


def is_section(key: str) -> bool:
    """True when ``buildingparser.<key>`` holds declared settings below it."""
    return any(k.startswith(key + ".") for k in SCHEMA)


# -- reading -----------------------------------------------------------------------------------------------

def setting(key: str) -> Any:
    """The validated, typed value of the setting ``buildingparser.<key>``.

    Parameters
    ----------
    key
        A declared key with dashes, e.g. ``crf.time-limit``.

    Returns
    -------
    The value converted to its declared type (None for null, or for a key that neither a YAML
    file nor :data:`SCHEMA_DEFAULTS` sets).

    Raises
    ------
    SettingsError
        When the value is not what the key's declaration accepts.
    """
    spec = SCHEMA.get(key)
    if spec is None:
        raise KeyError(f"{ROOT}.{key} is not a declared setting")
    value = dask.config.get(f"{ROOT}.{key}", _ABSENT)
    if value is _ABSENT:
        if key not in SCHEMA_DEFAULTS:
            return None  # declared for a dataclass field that no YAML file sets: the field's default
        value = SCHEMA_DEFAULTS[key]
    try:
        return spec.check(value)
    except ValueError as exc:
        raise SettingsError(f"{ROOT}.{key}", value, str(exc)) from None


def settings_fields(cls: type, section: str, keys: Mapping[str, str] | None = None) -> dict[str, Any]:
    """Keyword arguments of the dataclass ``cls`` from the settings under ``buildingparser.<section>``.

    Parameters
    ----------
    cls
        A dataclass; field ``a_b`` is read from key ``a-b``.
    section
        The dotted section, e.g. ``spaces.walls``.
    keys
        ``{field: key}``: read only these fields, from these keys (default: every field whose key is
        declared in the section).

    A null value leaves the field out (its default).  A field whose default is a dataclass and whose key
    is a non-empty section is built from that section the same way.
    """
    names = dict(keys) if keys is not None else {f.name: f.name.replace("_", "-") for f in dataclasses.fields(cls)}
    defaults = {f.name: f for f in dataclasses.fields(cls)}
    kw: dict[str, Any] = {}
    for name, key in names.items():
        full = f"{section}.{key}"
        if full in SCHEMA:
            value = setting(full)
        elif is_section(full) and dask.config.get(f"{ROOT}.{full}", None):
            value = _nested(defaults[name], full)
        else:
            continue
        if value is not None:
            kw[name] = value
    return kw


def _nested(f: dataclasses.Field, section: str) -> Any:
    """The dataclass field ``f`` (whose default is a dataclass) built from ``section``."""
    factory: Any = f.default_factory
    default = f.default if f.default is not dataclasses.MISSING else factory()
    if not dataclasses.is_dataclass(default) or isinstance(default, type):
        raise TypeError(f"{ROOT}.{section} is a section but field {f.name} holds no settings dataclass")
    cls: Any = type(default)
    return cls(**settings_fields(cls, section))


# -- checking everything at once ------------------------------------------------------------------------

def validate_settings() -> None:
    """Check the whole ``buildingparser`` tree against the schema before any work starts.

    Call it once every package's schema is declared (importing :mod:`engine.config` declares the
    engine's).  Raises a one-line :class:`SettingsError` naming the first unknown key (a likely typo)
    or bad value and what is expected.
    """
    tree = dask.config.get(ROOT, {})
    if not isinstance(tree, Mapping):
        raise SettingsError(ROOT, tree, "a section of settings (a mapping)")
    _validate_section(tree, "")
    for lo, hi in ORDERED:
        a, b = setting(lo), setting(hi)
        if a is not None and b is not None and a > b:
            raise SettingsError(f"{ROOT}.{lo}", a, f"<= {ROOT}.{hi} ({b})")


def _validate_section(tree: Mapping[str, Any], prefix: str) -> None:
    for k, value in tree.items():
        key = prefix + str(k).replace("_", "-")
        if key in SCHEMA:
            try:
                SCHEMA[key].check(value)
            except ValueError as exc:
                raise SettingsError(f"{ROOT}.{key}", value, str(exc)) from None
        elif is_section(key):
            if not isinstance(value, Mapping):
                raise SettingsError(f"{ROOT}.{key}", value, "a section of settings (a mapping)")
            _validate_section(value, key + ".")
        else:
            raise SettingsError(f"{ROOT}.{key}", value, hint=_unknown(key))


def _unknown(key: str) -> str:
    """The message of an unknown key, with the closest declared key when one is close."""
    known = list(SCHEMA) + sorted({k.rpartition(".")[0] for k in SCHEMA if "." in k})
    close = difflib.get_close_matches(key, known, n=1, cutoff=0.75)
    hint = f" (did you mean {ROOT}.{close[0]}?)" if close else ""
    return f"unknown setting {ROOT}.{key}{hint}"


def non_default_settings() -> dict[str, Any]:
    """Every declared ``buildingparser.*`` setting whose value differs from its default: dotted key -> value.

    The default of a key is what the packages' YAML files (dask's registered defaults) or
    :data:`SCHEMA_DEFAULTS` give it; both sides go through the key's declaration, so ``"20"`` and ``20``
    are one value.
    """
    registered = dask.config.merge(*dask.config.defaults).get(ROOT, {})
    out: dict[str, Any] = {}
    for key, spec in sorted(SCHEMA.items()):
        node: Any = registered
        for part in key.split("."):
            node = node.get(part, _ABSENT) if isinstance(node, Mapping) else _ABSENT
        if node is _ABSENT:
            node = SCHEMA_DEFAULTS.get(key)
        try:
            default = None if node is None else spec.check(node)
        except ValueError:
            default = node
        value = setting(key)
        if value != default:
            out[key] = value
    return out


# -- this package's settings ---------------------------------------------------------------------------

declare({
    "progress": "one of auto, always, never",
    "retries": "int >= 0",
    "tiles": {"size": "float > 0"},
    "ingest": {"part-points": "int >= 1", "scale": "float > 0", "bad-lines": "one of error, skip",
               "s3dis": {"check-room-files": "bool"}},
    "export": {"part-points": "int >= 1", "window": "int >= 1 | null", "scratch": "str | null"},
    "copc": {"node-points": "int >= 1", "group-points": "int >= 1"},
})
register()
