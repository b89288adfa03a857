"""The nightly harness flags quality drops and slowdowns beyond the noise of its history, and only those."""
from __future__ import annotations

from benchmarks.__main__ import compare


def _hist(values, key="s.ari", kind="quality", better="higher"):
    return [{"tracked": {key: {"value": v, "kind": kind, "better": better}}} for v in values]


def test_quality_drop_beyond_noise_is_flagged():
    rows = compare({"s.ari": {"value": 0.90, "kind": "quality", "better": "higher"}}, _hist([0.95, 0.951, 0.949]))
    assert rows[0]["flag"] == "QUALITY DROP"


def test_change_within_noise_is_not_flagged():
    hist = _hist([0.95, 0.90, 0.96, 0.91])  # noisy history: 3 sd is about 0.08
    rows = compare({"s.ari": {"value": 0.90, "kind": "quality", "better": "higher"}}, hist)
    assert rows[0]["flag"] == ""


def test_slowdown_of_a_lower_is_better_ratio_is_flagged():
    hist = _hist([1.0, 1.02, 0.98], key="s.ratio", kind="speed", better="lower")
    rows = compare({"s.ratio": {"value": 1.4, "kind": "speed", "better": "lower"}}, hist)
    assert rows[0]["flag"] == "SLOWDOWN"
    rows = compare({"s.ratio": {"value": 1.05, "kind": "speed", "better": "lower"}}, hist)
    assert rows[0]["flag"] == ""


def test_first_result_has_nothing_to_compare():
    rows = compare({"s.ari": {"value": 0.5, "kind": "quality", "better": "higher"}}, [])
    assert rows[0]["previous"] == "" and rows[0]["flag"] == ""


def test_peak_memory_counts_children_and_finds_new_ones_after_its_refresh():
    """The sampler sums this process and its children; a child started later is found within ``refresh``."""
    import subprocess
    import sys
    import time

    from benchmarks.common import PeakMemory

    grow = "import time; b = bytearray(300 * 2**20); b[::4096] = b'x' * len(b[::4096]); time.sleep(3)"
    with PeakMemory(interval=0.02, refresh=0.2) as mem:
        time.sleep(0.3)
        alone = mem.peak_total
        child = subprocess.Popen([sys.executable, "-c", grow])
        time.sleep(2.0)
        child.kill()
        child.wait()
    assert mem.peak_single >= 300 * 2**20  # the child, found after the sampler started
    assert mem.peak_total >= alone + 300 * 2**20
