"""A run's analysis, the same for lock-step and networked runs: the series layout and the
accuracy metrics."""
