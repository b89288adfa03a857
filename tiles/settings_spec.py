"""What a setting's value must be: :class:`Spec`, parsed from a short declaration such as ``"float > 0 | null"``.

A spec checks a value and returns it typed (``int``, ``float``, ``bool``, a tuple of names...), or raises a
``ValueError`` whose message says what is expected (``a number > 0``).  The registry of declared settings and
the loader are in :mod:`tiles.config`; see ``docs/design/settings.md``.
"""
from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from tiles.classes import ELEMENT_CLASSES

_BOUND = re.compile(r"^(>=|>|<=|<)\s*(\S+)$")
_RANGE = re.compile(r"^in\s*([\[(])\s*([^,\s]+)\s*,\s*([^\])\s]+)\s*([\])])$")
_TRUE, _FALSE = ("true", "yes", "on", "1"), ("false", "no", "off", "0")


@dataclass(frozen=True)
class Spec:
    """What one setting's value must be, parsed from a declaration such as ``"float > 0 | null"``.

    Declarations: ``float`` / ``int`` with an optional bound (``> 0``, ``>= 1``, ``in [0, 1]``,
    ``in (0, 0.5)``); ``bool``; ``str``; ``one of a, b, c``; ``classes`` (element class names, a
    comma-separated string or a list); ``names of a, b, c`` (a subset, the same forms); ``floats > 0``
    (a non-empty list of numbers, with the bound); ``classes -> int >= 0`` (a mapping of element class
    to a value); ``duration`` (``20s`` or seconds); ``memory`` (``auto``, ``4GiB`` or bytes).
    A trailing ``| null`` accepts null.
    """

    text: str
    kind: str
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple[str, ...] = ()
    inner: Spec | None = None
    nullable: bool = False

    @classmethod
    def parse(cls, text: str) -> Spec:
        """The spec of a declaration (a ``ValueError`` when the declaration itself is malformed)."""
        body, nullable = text.strip(), False
        if body.endswith("| null"):
            body, nullable = body[: -len("| null")].strip(), True
        if body.startswith("classes ->"):
            return cls(text, "classmap", inner=cls.parse(body[len("classes ->"):]), nullable=nullable)
        for prefix, kind in (("one of ", "choice"), ("names of ", "names")):
            if body.startswith(prefix):
                names = tuple(n.strip() for n in body[len(prefix):].split(",") if n.strip())
                return cls(text, kind, choices=names, nullable=nullable)
        kind, _, bound = body.partition(" ")
        if kind not in ("float", "int", "floats", "bool", "str", "classes", "duration", "memory"):
            raise ValueError(f"unknown setting declaration {text!r}")
        if not bound.strip():
            return cls(text, kind, nullable=nullable)
        if m := _RANGE.match(bound.strip()):
            return cls(text, kind, float(m[2]), float(m[3]), m[1] == "(", m[4] == ")", nullable=nullable)
        if m := _BOUND.match(bound.strip()):
            op, v = m[1], float(m[2])
            lo, hi = (v, None) if op.startswith(">") else (None, v)
            return cls(text, kind, lo, hi, op == ">", op == "<", nullable=nullable)
        raise ValueError(f"unknown bound in setting declaration {text!r}")

    def expected(self) -> str:
        """What the value must be, in words (``a number > 0``)."""
        what = {"float": "a number", "int": "an integer", "floats": "a non-empty list of numbers",
                "bool": "true or false", "str": "a string",
                "classes": "comma-separated element classes (" + ", ".join(ELEMENT_CLASSES) + ")",
                "duration": "a duration (e.g. 20s, 2min) or a number of seconds",
                "memory": "auto, a size (e.g. 4GiB) or a number of bytes",
                "choice": "one of " + ", ".join(self.choices),
                "names": "comma-separated names from " + ", ".join(self.choices),
                "classmap": f"a mapping of element class to {self.inner.expected() if self.inner else ''}"}[self.kind]
        what += self._bound_text()
        return what + " or null" if self.nullable else what

    def _bound_text(self) -> str:
        def num(v: float) -> str:
            return str(int(v)) if float(v).is_integer() else str(v)

        if self.lo is not None and self.hi is not None:
            return f" in {'(' if self.lo_open else '['}{num(self.lo)}, {num(self.hi)}{')' if self.hi_open else ']'}"
        if self.lo is not None:
            return f" {'>' if self.lo_open else '>='} {num(self.lo)}"
        if self.hi is not None:
            return f" {'<' if self.hi_open else '<='} {num(self.hi)}"
        return ""

    def check(self, value: Any) -> Any:
        """The typed value (``int``, ``float``, ``bool``, a tuple of names...); ``ValueError`` if it is not one."""
        if value is None:
            if self.nullable:
                return None
            raise ValueError(self.expected())
        typed = _CONVERT[self.kind](self, value)
        if self.kind in ("float", "int") and not self._in_bounds(typed):
            raise ValueError(self.expected())
        return typed

    def _in_bounds(self, v: float) -> bool:
        if self.lo is not None and (v < self.lo or (self.lo_open and v == self.lo)):
            return False
        return not (self.hi is not None and (v > self.hi or (self.hi_open and v == self.hi)))


def _to_float(spec: Spec, v: Any) -> float:
    if isinstance(v, bool):
        raise ValueError(spec.expected())
    try:
        f = float(v.strip() if isinstance(v, str) else v)
    except (TypeError, ValueError):
        raise ValueError(spec.expected()) from None
    if not math.isfinite(f):
        raise ValueError(spec.expected())
    return f


def _to_int(spec: Spec, v: Any) -> int:
    if isinstance(v, int) and not isinstance(v, bool):
        return int(v)
    f = _to_float(spec, v)
    if not f.is_integer():
        raise ValueError(spec.expected())
    return int(f)


def _to_bool(spec: Spec, v: Any) -> bool:
    if isinstance(v, bool):
        return v
    if isinstance(v, int) and v in (0, 1):
        return bool(v)
    if isinstance(v, str) and v.strip().lower() in _TRUE + _FALSE:
        return v.strip().lower() in _TRUE
    raise ValueError(spec.expected())


def _to_str(spec: Spec, v: Any) -> str:
    if not isinstance(v, str):
        raise ValueError(spec.expected())
    return v


def _to_choice(spec: Spec, v: Any) -> str:
    if not isinstance(v, str) or v.strip() not in spec.choices:
        raise ValueError(spec.expected())
    return v.strip()


def _to_names(spec: Spec, v: Any) -> tuple[str, ...]:
    known = ELEMENT_CLASSES if spec.kind == "classes" else spec.choices
    if isinstance(v, str):
        names = tuple(n.strip() for n in v.split(",") if n.strip())
    elif isinstance(v, (list, tuple)) and all(isinstance(n, str) for n in v):
        names = tuple(n.strip() for n in v if n.strip())
    else:
        raise ValueError(spec.expected())
    if any(n not in known for n in names):
        raise ValueError(spec.expected())
    return names


def _to_floats(spec: Spec, v: Any) -> tuple[float, ...]:
    if not isinstance(v, (list, tuple)) or not v:
        raise ValueError(spec.expected())
    item = dataclasses.replace(spec, kind="float", nullable=False)
    try:
        return tuple(item.check(x) for x in v)
    except ValueError:
        raise ValueError(spec.expected()) from None


def _to_classmap(spec: Spec, v: Any) -> dict[str, Any]:
    inner = spec.inner
    if inner is None or not isinstance(v, Mapping) or any(k not in ELEMENT_CLASSES for k in v):
        raise ValueError(spec.expected())
    try:
        return {k: inner.check(x) for k, x in v.items()}
    except ValueError:
        raise ValueError(spec.expected()) from None


def _to_duration(spec: Spec, v: Any) -> Any:
    from dask.utils import parse_timedelta

    try:
        ok = not isinstance(v, bool) and parse_timedelta(v) >= 0
    except (TypeError, ValueError, KeyError):
        ok = False
    if not ok:
        raise ValueError(spec.expected())
    return v


def _to_memory(spec: Spec, v: Any) -> Any:
    from dask.utils import parse_bytes

    if isinstance(v, str) and v.strip() == "auto":
        return v
    try:
        ok = not isinstance(v, bool) and (parse_bytes(v) if isinstance(v, str) else float(v)) > 0
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(spec.expected())
    return v


_CONVERT = {"float": _to_float, "int": _to_int, "bool": _to_bool, "str": _to_str, "choice": _to_choice,
            "classes": _to_names, "names": _to_names, "floats": _to_floats, "classmap": _to_classmap,
            "duration": _to_duration, "memory": _to_memory}
