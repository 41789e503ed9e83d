"""Map a vehicle's time_boot_ms onto the agent's clock.

offset = receive time - boot time is smallest for the least-delayed packet, so
the running minimum estimates the true offset plus the smallest transport delay.
A boot time going backwards means the vehicle rebooted: start over.
"""

from __future__ import annotations

import math

REBOOT_JUMP_S = 1.0


class BootClockMap:
    """Running-minimum offset between vehicle boot time and the agent clock."""

    def __init__(self) -> None:
        self.offset_s = math.inf
        self._last_boot_s = -math.inf
        self.resets = 0

    def stamp(self, boot_s: float, received_s: float) -> float:
        """Agent-clock time of a sample the vehicle stamped `boot_s`, received at `received_s`."""
        if boot_s < self._last_boot_s - REBOOT_JUMP_S:
            self.offset_s = math.inf
            self.resets += 1
        self._last_boot_s = boot_s
        self.offset_s = min(self.offset_s, received_s - boot_s)
        return boot_s + self.offset_s
