"""Every benchmark suite still runs: ``python -m benchmarks --quick`` on tiny inputs, as ``make bench-quick``."""
from __future__ import annotations

import os
import pathlib
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.mark.timeout(1500)
def test_every_suite_runs_in_quick_mode(tmp_path):
    env = {**os.environ, "BUILDINGPARSER_BENCH_CACHE": str(tmp_path / "cache"), "MPLBACKEND": "Agg"}
    proc = subprocess.run([sys.executable, "-m", "benchmarks", "--quick", "--no-save"], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=1450)
    tail = proc.stdout[-3000:] + proc.stderr[-3000:]
    assert proc.returncode == 0, tail
    suites = subprocess.run([sys.executable, "-m", "benchmarks", "--list"], cwd=ROOT, capture_output=True,
                            text=True, check=True).stdout.split()
    assert suites and all(f"### {s} (quick)" in proc.stdout for s in suites), tail
    assert f"{len(suites)} suites in" in proc.stdout and "; 0 failed;" in proc.stdout, tail
    assert "== comparison with the previous result ==" in proc.stdout
