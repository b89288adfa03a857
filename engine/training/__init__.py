"""Training of the detectors (paper Sec. 4): linear SVMs per class with hard-negative mining, feature-group
validation, ablations."""
