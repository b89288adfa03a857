"""Space parsing (paper Sec. 3.1) and the space update (Sec. 4.2).

Alignment, density histograms, peak-gap-peak dividers, slicing, merging, refinement, and the update.
"""
