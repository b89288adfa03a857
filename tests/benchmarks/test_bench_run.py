"""bench_run's stage profile: idle and serial time from a task stream and the stage lines."""
from __future__ import annotations

import pytest

from benchmarks.bench_run import _busy_profile, stage_profile


def test_busy_profile_splits_the_window_by_how_many_workers_run():
    # worker a busy 0-4, worker b busy 2-6 and 7-8; window 0-10
    p = _busy_profile([[(0.0, 4.0)], [(2.0, 6.0), (7.0, 8.0)]], 0.0, 10.0)
    assert p == pytest.approx({"none_busy_s": 3.0, "one_busy_s": 5.0, "all_busy_s": 2.0})
    clipped = _busy_profile([[(0.0, 4.0)], [(2.0, 6.0)]], 3.0, 5.0)  # spans cut at the window
    assert clipped == pytest.approx({"none_busy_s": 0.0, "one_busy_s": 1.0, "all_busy_s": 1.0})


def test_stage_profile_charges_tasks_and_cpu_to_the_stage_they_ran_in():
    stream = [{"worker": "a", "startstops": [{"action": "compute", "start": 1.0, "stop": 3.0}]},
              {"worker": "b", "startstops": [{"action": "compute", "start": 2.0, "stop": 12.0},
                                             {"action": "transfer", "start": 0.0, "stop": 1.0}]}]
    marks = [(5.0, "ingest: 10 points", 2.0, 6.0), (6.0, "not a stage line", 2.5, 7.0),
             (14.0, "spaces: 1 spaces", 3.0, 14.0), (15.0, "end", 4.0, 14.0)]
    rows = stage_profile(stream, marks, (0.0, 1.0, 0.0), workers=2)
    assert [r["stage"] for r in rows] == ["ingest", "spaces", "metrics+outputs"]
    ingest, spaces, rest = rows
    assert (ingest["wall_s"], ingest["driver_cpu_s"], ingest["worker_cpu_s"]) == (5.0, 1.0, 6.0)
    assert ingest["task_s"] == 5.0 and ingest["idle_worker_s"] == 5.0  # a: 1-3, b: 2-5
    assert (ingest["none_busy_s"], ingest["one_busy_s"], ingest["all_busy_s"]) == (1.0, 3.0, 1.0)
    assert spaces["task_s"] == 7.0 and spaces["none_busy_s"] == 2.0 and spaces["one_busy_s"] == 7.0
    assert rest["task_s"] == 0.0 and rest["none_busy_s"] == 1.0 and rest["driver_cpu_s"] == 1.0


def test_scaling_summary_is_the_ratio_of_the_medians_of_interleaved_runs():
    from benchmarks.bench_run import scaling_summary

    one = scaling_summary([100.0], [60.0])
    assert one["speedup_2_vs_1"] == pytest.approx(1.67) and "speedup_per_pair" not in one
    many = scaling_summary([100.0, 120.0, 104.0], [60.0, 62.0, 58.0])  # medians 104 and 60
    assert many["speedup_2_vs_1"] == pytest.approx(1.73)
    assert many["speedup_per_pair"] == [1.67, 1.94, 1.79] and many["repeat"] == 3


def test_repeat_must_be_a_positive_count():
    from benchmarks.bench_run import run

    with pytest.raises(ValueError, match="repeat"):
        run(repeat=0)


def test_stages_are_reported_as_multiples_of_the_median_decode_with_their_efficiency():
    from benchmarks.bench_run import decode_table

    stages = {"spaces": [9.0, 11.0, 10.0], "detection": [30.0, 28.0, 40.0], "export": [5.0, 5.0, 5.0],
              "whole run": [60.0, 70.0, 65.0]}
    profile = [{"stage": "spaces", "wall_s": 10.0, "worker_cpu_s": 15.0},
               {"stage": "detection", "wall_s": 30.0, "worker_cpu_s": 57.0},
               {"stage": "export", "wall_s": 5.0, "worker_cpu_s": 5.0}]
    rows = {r["stage"]: r for r in decode_table(stages, [5.0, 4.0, 6.0], profile, workers=2)}  # median decode 5 s
    assert rows["spaces"]["x_decode"] == 2.0 and rows["spaces"]["met"] is True
    assert rows["detection"]["x_decode"] == 6.0 and rows["detection"]["met"] is False  # target 3x
    assert rows["whole run"]["x_decode"] == 13.0 and rows["whole run"]["target_x"] == 8.0
    assert rows["spaces"]["parallel_efficiency"] == 0.75 and rows["detection"]["parallel_efficiency"] == 0.95
    assert rows["export"]["parallel_efficiency"] == 0.5
    assert rows["whole run"]["parallel_efficiency"] == round(77.0 / (2 * 45.0), 2)
