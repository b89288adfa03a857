"""The contextual CRF (paper Sec. 4.1) as an integer program, its structured-SVM weights and their validation."""
