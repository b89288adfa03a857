"""Means over classes of per-class values (AP, IoU) where a class without data is NaN."""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def nanmean(values: Sequence[float]) -> float:
    """The mean of the values that are not NaN; NaN when none is."""
    v = np.asarray(values, dtype=float)
    v = v[~np.isnan(v)]
    return float(v.mean()) if len(v) else float("nan")
