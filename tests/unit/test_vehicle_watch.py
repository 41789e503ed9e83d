"""The agent notices its vehicle stopped flying its setpoints (failsafe, reboot, silence)."""

from __future__ import annotations

from agents.mavlink.adapter import VehicleState
from agents.shell.vehicle_loop import RECOVER_AFTER_S, VehicleWatch

FLYING = VehicleState((0.0, 0.0, 10.0), (0.0, 0.0, 0.0), 0.0, True, "OFFBOARD", True)


def test_flying_is_never_lost() -> None:
    w = VehicleWatch()
    assert not any(w.lost(FLYING, "px4", 0.1 * k) for k in range(100))


def test_failsafe_hold_is_left_to_the_offboard_keeper() -> None:
    w = VehicleWatch(0.0)
    assert not any(w.lost(FLYING._replace(mode="HOLD"), "px4", 0.1 * k) for k in range(10))


def test_other_modes_and_reboot_are_lost_after_the_grace() -> None:
    for state in (FLYING._replace(mode="LAND"), FLYING._replace(armed=False)):
        w = VehicleWatch()
        assert not w.lost(state, "px4", 10.0)
        assert not w.lost(state, "px4", 10.0 + 0.9 * RECOVER_AFTER_S)
        assert w.lost(state, "px4", 10.0 + RECOVER_AFTER_S)
        assert not w.lost(FLYING, "px4", 11.0)  # back: the clock starts over
        assert not w.lost(state, "px4", 11.1)


def test_silence_is_waited_for_and_the_vehicle_judged_when_heard_again() -> None:
    w = VehicleWatch()
    silent = FLYING._replace(link_ok=False)
    # However long: a start-up could not run without the vehicle, and would stop the loop.
    assert not any(w.lost(silent, "px4", 10.0 + 0.5 * k) for k in range(60))
    # A simulator that restarted: heard again, disarmed, after the grace from then.
    rebooted = FLYING._replace(armed=False, mode="MANUAL")
    assert not w.lost(rebooted, "px4", 40.0)
    assert w.lost(rebooted, "px4", 40.0 + RECOVER_AFTER_S)
    # Silence while a wrong mode was being timed restarts the grace.
    w = VehicleWatch()
    assert not w.lost(rebooted, "px4", 50.0)
    assert not w.lost(silent, "px4", 50.4)
    assert not w.lost(rebooted, "px4", 50.6)
    assert w.lost(rebooted, "px4", 50.6 + RECOVER_AFTER_S)


def test_ardupilot_guided_is_flying() -> None:
    assert not VehicleWatch(0.0).lost(FLYING._replace(mode="GUIDED"), "ardupilot", 1.0)
