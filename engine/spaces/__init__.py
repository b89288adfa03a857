"""Space parsing (paper Sec. 3.1): alignment, density histograms, peak-gap-peak dividers, slicing, merging, refinement, and the space update (Sec. 4.2)."""
