"""Keep flying offboard after the vehicle's setpoint-loss failsafe, without blocking.

When our process stalls (a pause, swapping, a busy onboard computer) the autopilot
sees its setpoint stream stop and, as PX4 (COM_OF_LOSS_T) and the simulator do,
falls back to Hold.  Once setpoints flow again, a companion re-requests its mode, as
MAVROS-based offboard programs do.  Only the failsafe's Hold is undone: any other
mode (Land, a pilot's choice) is somebody else's decision and stays.
"""

from __future__ import annotations

import logging
import math

from agents.mavlink.adapter import MavlinkAdapter
from agents.mavlink.modes import HOLD_MODE, OFFBOARD_MODE, do_set_mode_params

log = logging.getLogger(__name__)
MAV_CMD_DO_SET_MODE = 176


class OffboardKeeper:
    """Call `check(now_s)` after each tick's setpoint; re-requests offboard every retry_s."""

    def __init__(self, vehicle: MavlinkAdapter, retry_s: float = 0.5) -> None:
        self.vehicle = vehicle
        self.retry_s = retry_s
        self.requests = 0
        self.recoveries = 0
        self._last_try_s = -math.inf
        self._lost = False

    def check(self, now_s: float) -> None:
        ad, state = self.vehicle, self.vehicle.state
        if ad.flavour is None or not state.armed or not state.link_ok:
            return
        if state.mode == OFFBOARD_MODE[ad.flavour]:
            if self._lost:
                self._lost = False
                self.recoveries += 1
                log.info("vehicle %s back in %s", ad.sysid, state.mode)
            return
        if state.mode != HOLD_MODE[ad.flavour] or now_s - self._last_try_s < self.retry_s:
            return
        if not self._lost:
            self._lost = True
            log.warning("vehicle %s left %s for %s (setpoint-loss failsafe?): re-requesting",
                        ad.sysid, OFFBOARD_MODE[ad.flavour], state.mode)
        self._last_try_s = now_s
        self.requests += 1
        ad.send_command(MAV_CMD_DO_SET_MODE,
                        do_set_mode_params(ad.flavour, OFFBOARD_MODE[ad.flavour]))
