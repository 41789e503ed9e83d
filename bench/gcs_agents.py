"""The agents' MAVLink traffic to a simulator, signed as each follower signs it: the load
the simulator benchmarks (bench_process_cost.py, sim_phases.py) send."""

from __future__ import annotations

import time

from pymavlink.dialects.v20 import common as mavlink2

from agents.mavlink.modes import do_set_mode_params
from agents.mavlink.signing import signing_timestamp
from agents.mavlink.signing_keys import vehicle_key
from agents.mavlink.startup import (
    MAV_CMD_COMPONENT_ARM_DISARM,
    MAV_CMD_DO_SET_MODE,
    MAV_CMD_SET_MESSAGE_INTERVAL,
    StartupTimeouts,
    stream_rates,
)
from agents.mavlink.wire import encode, encode_fields, new_codec, sign_outgoing

HOST = "127.0.0.1"
GCS_SYSID, GCS_COMPID = 245, 191


class Agents:
    """One signing ground-station codec per vehicle (link i, vehicle i+1's key)."""

    def __init__(self, secret: bytes, n: int, ask_rates: bool = True) -> None:
        self.ask_rates = ask_rates  # False: the vehicles stream at their default rates
        self.codecs = []
        for i in range(n):
            mav = new_codec(GCS_SYSID, GCS_COMPID, mavlink2)
            sign_outgoing(mav, vehicle_key(secret, i + 1), i, signing_timestamp(time.time()))
            self.codecs.append(mav)

    def setpoint(self, i: int) -> bytes:
        # type_mask 3527: velocity only (what the followers send)
        return encode_fields(self.codecs[i], mavlink2.MAVLink_set_position_target_local_ned_message,
                             0, 0.0, 0.0, 0.0, 0.5, 0.0, -0.2, 0.0, 0.0, 0.0, 0.0, 0.0, 3527,
                             i + 1, 1, 1)

    def heartbeat(self, i: int) -> bytes:
        mav = self.codecs[i]
        return encode(mav, mav.heartbeat_encode(6, 8, 0, 0, 4))

    def timesync(self, i: int) -> bytes:
        return encode_fields(self.codecs[i], mavlink2.MAVLink_timesync_message, 0,
                             time.monotonic_ns())

    def command(self, i: int, cmd: int, *params: float) -> bytes:
        mav = self.codecs[i]
        p = list(params) + [0.0] * (7 - len(params))
        return encode(mav, mav.command_long_encode(i + 1, 1, cmd, 0, *p))

    def start(self, i: int) -> list[bytes]:
        """What a follower asks once setpoints stream: its telemetry rates
        (agents.mavlink.startup.stream_rates: ATTITUDE and GLOBAL_POSITION_INT down to
        4 Hz), OFFBOARD, then arm."""
        rates = [self.command(i, MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz)
                 for msg_id, hz in stream_rates(StartupTimeouts()) if self.ask_rates]
        offboard = do_set_mode_params("px4", "OFFBOARD")
        return [*rates, self.command(i, MAV_CMD_DO_SET_MODE, *offboard),
                self.command(i, MAV_CMD_COMPONENT_ARM_DISARM, 1.0)]
