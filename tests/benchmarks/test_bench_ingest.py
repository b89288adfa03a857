"""bench_ingest's options (its quick run is in test_quick)."""
from __future__ import annotations

import sys

import pytest

from benchmarks import bench_ingest


@pytest.mark.parametrize("repeat", [0, -1, 1.5])
def test_a_repeat_that_is_not_a_positive_count_is_refused_before_any_work(repeat):
    with pytest.raises(ValueError, match="repeat must be a positive number"):
        bench_ingest.run(quick=True, repeat=repeat)


def test_the_command_line_refuses_a_zero_repeat(monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["bench_ingest", "--quick", "--repeat", "0"])
    with pytest.raises(SystemExit) as exc:
        bench_ingest.main()
    assert exc.value.code == 2 and "--repeat must be at least 1" in capsys.readouterr().err
