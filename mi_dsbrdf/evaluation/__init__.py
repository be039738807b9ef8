"""Error measures and synthetic experiments with known truth (paper Sec. 6), and the Adam baseline."""
