"""Benchmarks: each ``bench_*.py`` module has ``run(quick=False) -> dict`` and prints JSON and a table.

Every figure is measured next to its reference in the same run, so a noisy
machine still gives a fair ratio.  Run one with ``python -m benchmarks.bench_ingest``.
"""
