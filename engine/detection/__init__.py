"""Element detection (paper Sec. 3.2, 4).

Canonical frames, voxel features, the window dictionary, sliding windows, box regression and re-ranking, and the
model file.
"""
