"""Warnings that a sender can provoke, logged at most once a period per topic.

A flood of forged or malformed input must be visible in the log without becoming a flood
of log lines (disk, and the CPU of the process that writes them): per topic -- a reason
such as `rejected_sender` -- the first occurrence is logged, the next ones within
`period_s` only counted, and the next line logged says how many were not.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

LOG_PERIOD_S = 10.0
MAX_TOPICS = 64  # topics are reasons, a fixed set; beyond this they share one


class RateLimitedLog:
    def __init__(self, logger: logging.Logger, period_s: float = LOG_PERIOD_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.logger, self.period_s, self.clock = logger, period_s, clock
        self._next_s: dict[str, float] = {}
        self._quiet: dict[str, int] = {}  # per topic, occurrences not logged since its last line
        self.lines = 0

    def warning(self, topic: str, fmt: str, *args: object) -> None:
        """Log `fmt % args` unless `topic` was logged less than `period_s` ago (the text
        is formatted only then: a flood costs a lookup per occurrence)."""
        if topic not in self._next_s and len(self._next_s) >= MAX_TOPICS:
            topic = "other"
        now = self.clock()
        if now < self._next_s.get(topic, -float("inf")):
            self._quiet[topic] = self._quiet.get(topic, 0) + 1
            return
        self._next_s[topic] = now + self.period_s
        quiet = self._quiet.pop(topic, 0)
        more = f" (and {quiet} more since the last such line)" if quiet else ""
        self.logger.warning(fmt + "%s", *args, more)
        self.lines += 1
