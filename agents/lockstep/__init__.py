"""The lock-step engine: the closed loop in one process, without clock or network (the paper's
law compiled, or any law)."""
