"""The agent notices its vehicle stopped flying its setpoints (failsafe, reboot, silence)."""

from __future__ import annotations

from dataclasses import replace

from agents.mavlink.adapter import VehicleState
from agents.vehicle_loop import RECOVER_AFTER_S, VehicleWatch

FLYING = VehicleState((0.0, 0.0, 10.0), (0.0, 0.0, 0.0), 0.0, True, "OFFBOARD", True)


def test_flying_is_never_lost() -> None:
    w = VehicleWatch()
    assert not any(w.lost(FLYING, "px4", 0.1 * k) for k in range(100))


def test_failsafe_hold_is_left_to_the_offboard_keeper() -> None:
    w = VehicleWatch(0.0)
    assert not any(w.lost(replace(FLYING, mode="HOLD"), "px4", 0.1 * k) for k in range(10))


def test_other_modes_reboot_and_silence_are_lost_after_the_grace() -> None:
    for state in (replace(FLYING, mode="LAND"), replace(FLYING, armed=False),
                  replace(FLYING, link_ok=False)):
        w = VehicleWatch()
        assert not w.lost(state, "px4", 10.0)
        assert not w.lost(state, "px4", 10.0 + 0.9 * RECOVER_AFTER_S)
        assert w.lost(state, "px4", 10.0 + RECOVER_AFTER_S)
        assert not w.lost(FLYING, "px4", 11.0)  # back: the clock starts over
        assert not w.lost(state, "px4", 11.1)


def test_ardupilot_guided_is_flying() -> None:
    assert not VehicleWatch(0.0).lost(replace(FLYING, mode="GUIDED"), "ardupilot", 1.0)
