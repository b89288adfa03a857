"""The 13 S3DIS classes and their codes, used everywhere (tiles, LAS classification, models)."""
from __future__ import annotations

CLASS_NAMES: tuple[str, ...] = (
    "ceiling", "floor", "wall", "beam", "column", "window", "door",
    "table", "chair", "sofa", "bookcase", "board", "clutter",
)
CLASS_CODES: dict[str, int] = {name: code for code, name in enumerate(CLASS_NAMES)}
CLUTTER = CLASS_CODES["clutter"]

#: The 12 element classes that are detected and scored (clutter is not an element).
ELEMENT_CLASSES: tuple[str, ...] = CLASS_NAMES[:12]
#: ``points.laz`` stores class ``c`` as LAS classification ``LAS_CLASS_OFFSET + c`` (64 ceiling ... 76
#: clutter): LAS 1.4 reserves 0-63 for the ASPRS classes, 64-255 are user-definable.
LAS_CLASS_OFFSET = 64
STRUCTURAL_CLASSES: tuple[str, ...] = ("ceiling", "floor", "wall", "beam", "column", "window", "door")
FURNITURE_CLASSES: tuple[str, ...] = ("table", "chair", "sofa", "bookcase", "board")


def element_class_list(value, key: str) -> tuple[str, ...]:
    """Element class names from a comma-separated string or a sequence (a setting's value).

    Unknown names are a ``ValueError`` naming the setting ``key``.
    """
    v = tuple(c.strip() for c in value.split(",") if c.strip()) if isinstance(value, str) else tuple(value or ())
    bad = [c for c in v if c not in ELEMENT_CLASSES]
    if bad:
        raise ValueError(f"{key}: unknown element class(es) {', '.join(bad)}")
    return v


def class_code(name: str) -> int:
    """Code of a class name; names outside the 13 classes (e.g. ``stairs``) are clutter."""
    return CLASS_CODES.get(name.strip().lower(), CLUTTER)


def las_class_lookup() -> dict[int, str]:
    """The LAS Classification Lookup of ``points.laz``: LAS class number -> name (64 ceiling ... 76 clutter)."""
    return {LAS_CLASS_OFFSET + code: name for code, name in enumerate(CLASS_NAMES)}
