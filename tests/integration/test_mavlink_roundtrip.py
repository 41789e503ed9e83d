"""The agents' adapter against the simulator as a real process: start-up, flight, link loss."""

from __future__ import annotations

import pytest

from agents.mavlink.adapter import AdapterConfig, MavlinkAdapter
from agents.mavlink.startup import StartupTimeouts, command, start_offboard, wait_until
from errors import CommandRejectedError, LinkLostError
from tests.integration.sim_process import start_sim

pytestmark = [pytest.mark.integration, pytest.mark.timeout(60)]
TIMEOUTS = StartupTimeouts(heartbeat_s=10.0, takeoff_s=15.0)


def fly(ad: MavlinkAdapter, vel_enu: tuple[float, float, float], seconds: float) -> None:
    end = ad.clock() + seconds
    while ad.clock() < end:
        assert ad.send_velocity_enu(vel_enu)
        ad.poll()
        ad.wait_readable(0.02)


@pytest.mark.parametrize("flavour", ["px4", "ardupilot"])
@pytest.mark.serial  # the link loss is timed to within a second: among the timed tests
@pytest.mark.xdist_group("timed-a")
def test_adapter_starts_flies_east_and_detects_link_loss(flavour: str) -> None:
    sim = start_sim("--flavour", flavour, vehicles=2)
    cfg = AdapterConfig.px4_sitl(1, local_base=sim.send_base, vehicle_base=sim.listen_base)
    ad = MavlinkAdapter(cfg).open()
    try:
        state = start_offboard(ad, altitude_m=2.0, t=TIMEOUTS)
        assert ad.flavour == flavour and ad.sysid == 2
        assert state.armed and state.mode == ("OFFBOARD" if flavour == "px4" else "GUIDED")
        assert state.pos_enu_m[2] == pytest.approx(2.0, abs=0.35)
        x0 = state.pos_enu_m[0]
        fly(ad, (1.5, 0.0, 0.0), 1.2)
        s = ad.poll()
        assert s.pos_enu_m[0] - x0 > 1.0 and s.vel_enu_m_s[0] == pytest.approx(1.5, abs=0.1)
        assert abs(s.vel_enu_m_s[1]) < 0.05
        assert 0.0 <= ad.clock() - s.stamp_s < 0.2  # telemetry stamped on our clock, fresh
        assert ad.counters["bad_packets"] == 0
        # Telemetry stops when SIGTERM arrives; the process may take a while longer to exit.
        lost = ad.clock()
        sim.stop()
        wait_until(ad, lambda st: not st.link_ok, 2.0, "link loss")
        assert 0.3 < ad.clock() - lost < 1.0
        with pytest.raises(LinkLostError):
            ad.check_link()
        assert ad.counters["link_losses"] == 1
    finally:
        ad.close()
        sim.stop()
    assert "sim stopped" in sim.output()


def test_bad_datagrams_are_counted_and_the_vehicle_keeps_answering() -> None:
    sim = start_sim()
    cfg = AdapterConfig.px4_sitl(0, local_base=sim.send_base, vehicle_base=sim.listen_base)
    ad = MavlinkAdapter(cfg).open()
    try:
        wait_until(ad, lambda s: s.link_ok and ad.flavour is not None, 10.0, "vehicle")
        assert ad.sock is not None and ad.remote is not None
        junk = ad.mav.command_long_encode(9, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(ad.mav)
        nan_sp = ad.mav.set_position_target_local_ned_encode(
            0, 1, 1, 1, 3527, 0, 0, 0, float("nan"), 0, 0, 0, 0, 0, 0, 0).pack(ad.mav)
        inf_sp = ad.mav.set_position_target_local_ned_encode(
            0, 1, 1, 8, 3527, 0, 0, 0, 0, float("inf"), 0, 0, 0, 0, 0, 0).pack(ad.mav)
        for payload in (b"", b"\xfd" * 300, bytes(range(256)) * 4, junk, junk[:7], nan_sp,
                        inf_sp, nan_sp[:-1] + b"\x00"):
            ad.sock.sendto(payload, ad.remote)
        # A refusal carries the vehicle's reason (its STATUSTEXT), as real autopilots send it.
        with pytest.raises(CommandRejectedError, match="not armed") as refused:
            command(ad, 22, (0.0,) * 6 + (float("nan"),), StartupTimeouts(command_s=2.0))
        assert refused.value.result == 2
        command(ad, 400, (1.0,), StartupTimeouts(command_s=2.0))
        state = wait_until(ad, lambda s: s.armed, 2.0, "armed")
        assert state.armed
    finally:
        ad.close()
        code = sim.stop()
    out = sim.output()
    assert code == 0
    counts = dict(kv.split("=") for kv in out.split("sim stopped:")[1].split() if "=" in kv)
    assert int(counts["bad_packets"]) >= 3
    assert int(counts["ignored_other_sysid"]) == 1
    assert int(counts["ignored_nonfinite"]) == 2
