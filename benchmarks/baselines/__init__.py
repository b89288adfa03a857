"""Baselines of paper Table 2 (RANSAC planes, 2D Hough lines) made into space parsers, for the benchmarks."""
