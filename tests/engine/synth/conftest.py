"""Small generated buildings shared by the synth tests (planned and scanned once per session)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from engine.synth import plan_building, scan_building


@pytest.fixture(scope="session")
def building():
    """One floor, ~450 m^2 with every room type, an L-shaped room, all 13 classes; ~0.5 M points."""
    return plan_building(5, area_m2=450, density=250)


@pytest.fixture(scope="session")
def scan(building):
    return scan_building(building)


@pytest.fixture(scope="session")
def tower():
    """Two floors, small and sparse: for stacking and slab tests."""
    return plan_building(5, area_m2=360, floors=2, density=120)


@pytest.fixture(scope="session")
def tower_scan(tower):
    return scan_building(tower)


@pytest.fixture(scope="session")
def hard():
    """Two floors, ~500 m^2, with every difficulty of real scans (hardness "all"); ~0.4 M points."""
    return plan_building(5, area_m2=500, floors=2, density=120, hardness="all")


@pytest.fixture(scope="session")
def hard_scan(hard):
    return scan_building(hard)


def xyz(cols) -> np.ndarray:
    return np.c_[cols["x"], cols["y"], cols["z"]]


def in_box(points: np.ndarray, element: dict, grow: float = 0.0) -> np.ndarray:
    """Which points lie inside a ground-truth element box (world coordinates, yaw about z)."""
    q = points - np.asarray(element["center"])
    c, s = math.cos(element["yaw"]), math.sin(element["yaw"])
    local = np.c_[c * q[:, 0] + s * q[:, 1], -s * q[:, 0] + c * q[:, 1], q[:, 2]]
    return np.all(np.abs(local) <= np.asarray(element["size"]) / 2 + grow, axis=1)


@pytest.fixture
def helpers():
    """Helper functions (importable fixtures: tests are collected in importlib mode)."""
    class H:
        pass

    H.xyz = staticmethod(xyz)
    H.in_box = staticmethod(in_box)
    return H
