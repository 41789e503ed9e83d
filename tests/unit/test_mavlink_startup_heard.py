"""Start-up timeouts count only the time the vehicle is heard (agents.mavlink.startup
HeardClock): a vehicle that went quiet because its simulator starved has refused nothing,
but one that stays quiet, or is heard and never answers, still fails, with a clear error.
An injected clock and a scripted vehicle: no sockets, no sleeps."""

from __future__ import annotations

import math
from typing import cast

import pytest

from agents.mavlink.adapter import MavlinkAdapter
from agents.mavlink.startup import StartupTimeouts, command, set_mode, wait_position
from agents.mavlink.vehicle_types import VehicleState
from errors import MavlinkError
from tests.unit.test_mavlink_adapter import ADDR, feed, heartbeat, make

pytestmark = pytest.mark.timeout(30)
T = StartupTimeouts(command_s=3.0, retry_s=0.5, silent_s=20.0)


class ScriptedVehicle:
    """The adapter surface start-up uses.  The vehicle is unheard from `quiet_from_s` to
    `quiet_until_s` (a starved simulator), streams telemetry otherwise, and ACKs command
    `cmd` (and reports mode `mode`) once `answers_at_s` has passed; time moves only in
    `wait_readable`."""

    def __init__(self, quiet_from_s: float, quiet_until_s: float, answers_at_s: float) -> None:
        self.t = 0.0
        self.quiet = (quiet_from_s, quiet_until_s)
        self.answers_at_s = answers_at_s
        self.acks: dict[int, int] = {}
        self.sent: list[tuple[float, int, int]] = []  # (time, command, confirmation)
        self.statustext_count = 0
        self.sysid, self.flavour, self.heard_s = 1, "px4", -math.inf
        self.telemetry_seen = True
        self._mode = "POSCTL"

    def clock(self) -> float:
        return self.t

    def _heard(self) -> bool:
        return not self.quiet[0] <= self.t < self.quiet[1]

    @property
    def state(self) -> VehicleState:
        return VehicleState((0.0, 0.0, 2.0), (0.0,) * 3, self.t, True, self._mode, self._heard())

    def poll(self) -> VehicleState:
        if self._heard():
            self.heard_s = self.t
            if self.t >= self.answers_at_s:
                self._mode = "OFFBOARD"
                for _, cmd, _ in self.sent:
                    self.acks[cmd] = 0
        return self.state

    def wait_readable(self, timeout_s: float) -> None:
        self.t += max(timeout_s, 1e-3)

    def send_command(self, cmd: int, params: tuple[float, ...], confirmation: int = 0) -> None:
        self.sent.append((self.t, cmd, confirmation))
        self.acks.pop(cmd, None)

    def send_velocity_enu(self, vel: tuple[float, float, float]) -> None:
        pass

    def statustexts_since(self, count: int) -> list[str]:
        return []


def test_a_vehicle_unheard_for_5_s_is_waited_for_not_given_up() -> None:
    v = ScriptedVehicle(quiet_from_s=0.2, quiet_until_s=5.2, answers_at_s=5.5)
    command(cast(MavlinkAdapter, v), 22, (0.0,) * 7, T)
    assert v.t == pytest.approx(5.5, abs=0.1)  # 5.5 s of wall time, 0.5 s of it heard
    confirmations = [c for _, _, c in v.sent]
    assert confirmations == list(range(len(confirmations))) and len(confirmations) >= 10


def test_a_heard_vehicle_that_never_acks_still_fails_after_command_s() -> None:
    v = ScriptedVehicle(quiet_from_s=1.0, quiet_until_s=2.0, answers_at_s=math.inf)
    with pytest.raises(MavlinkError, match=r"no COMMAND_ACK for command 22 within 3\.0 s"):
        command(cast(MavlinkAdapter, v), 22, (0.0,) * 7, T)
    assert v.t == pytest.approx(4.0, abs=0.1)  # 3 s heard + the 1-s gap


def test_a_vehicle_that_stays_silent_fails_after_silent_s_naming_what_we_waited_for() -> None:
    v = ScriptedVehicle(quiet_from_s=0.0, quiet_until_s=math.inf, answers_at_s=0.0)
    with pytest.raises(MavlinkError, match=r"unheard for 20\.0 s while waiting for the ACK"):
        command(cast(MavlinkAdapter, v), 400, (1.0,), T)
    assert v.t == pytest.approx(20.0, abs=0.1)


def test_mode_confirmation_waits_out_a_quiet_vehicle_too() -> None:
    v = ScriptedVehicle(quiet_from_s=0.1, quiet_until_s=6.0, answers_at_s=6.0)
    set_mode(cast(MavlinkAdapter, v), "OFFBOARD", T)
    assert v.state.mode == "OFFBOARD" and v.t >= 6.0


def test_position_is_waited_for_through_a_starved_simulators_silence() -> None:
    v = ScriptedVehicle(quiet_from_s=0.0, quiet_until_s=8.0, answers_at_s=0.0)
    state = wait_position(cast(MavlinkAdapter, v), T)  # position_s: 5 s
    assert state.link_ok and v.t == pytest.approx(8.0, abs=0.1)


class HeartbeatsOnly(ScriptedVehicle):
    """Heard (its HEARTBEATs), but it never streams a position."""

    def __init__(self) -> None:
        super().__init__(quiet_from_s=math.inf, quiet_until_s=math.inf, answers_at_s=0.0)
        self.telemetry_seen = False

    @property
    def state(self) -> VehicleState:
        return VehicleState((0.0,) * 3, (0.0,) * 3, self.t, True, self._mode, False)


def test_a_heard_vehicle_without_position_still_fails_after_position_s() -> None:
    v = HeartbeatsOnly()
    with pytest.raises(MavlinkError, match=r"5\.0 s waiting for LOCAL_POSITION_NED"):
        wait_position(cast(MavlinkAdapter, v), T)
    assert v.t == pytest.approx(5.0, abs=0.1)


def test_a_silent_vehicle_fails_the_position_wait_after_silent_s() -> None:
    v = ScriptedVehicle(quiet_from_s=0.0, quiet_until_s=math.inf, answers_at_s=0.0)
    with pytest.raises(MavlinkError, match=r"unheard for 20\.0 s while waiting for LOCAL_POS"):
        wait_position(cast(MavlinkAdapter, v), T)


def test_adapter_hears_its_vehicle_not_a_ground_station() -> None:
    ad, clock = make()
    assert ad.heard_s == -math.inf and not ad.telemetry_seen
    feed(ad, heartbeat(autopilot=8), clock.t, sysid=255)  # a GCS (MAV_AUTOPILOT_INVALID)
    assert ad.heard_s == -math.inf
    feed(ad, heartbeat(), clock.t)
    assert ad.heard_s == clock.t and ad.remote == ADDR
