"""A real simulator's TIMESYNC answer puts a client's clock map where its telemetry says.

The simulator reads its sockets once a tick, so a request sent just after a tick waits
nearly a tick before it is answered.  Answered with the clock at handling time, the
client's midpoint estimate would be off by half that wait (~10 ms at 50 Hz), the same
every time for a client that ticks in step with the simulator.  The answer is the
midpoint of the wait (sim_backend.arrival), so the offset a plain pymavlink client
computes from TIMESYNC must agree with the one its telemetry shows: LOCAL_POSITION_NED
stamped time_boot_ms t leaves at boot time t, so arrival minus stamp, at its smallest,
is the offset plus the fastest one-way trip.
"""

from __future__ import annotations

import statistics
import time

import pytest

from tests.integration.sim_process import PlainClient, start_sim

pytestmark = [pytest.mark.integration, pytest.mark.timeout(60)]
REQUESTS = 40
AGREE_S = 0.004  # a tick is 20 ms: half of it is the error this test is there to catch


def test_timesync_offset_agrees_with_the_telemetry_clock_when_requests_wait_a_tick() -> None:
    sim = start_sim(vehicles=1)
    client = PlainClient(sim.send_base, sim.listen_base)
    telemetry_offsets: list[float] = []
    timesync_offsets: list[float] = []
    try:
        client.until(lambda: "LOCAL_POSITION_NED" in client.last, 20.0, "telemetry")
        client.sock.settimeout(0.1)
        deadline = time.monotonic() + 30.0
        while len(timesync_offsets) < REQUESTS and time.monotonic() < deadline:
            data, _ = client.sock.recvfrom(65535)
            now_s = time.monotonic()
            for m in client.mav.parse_buffer(data) or []:
                kind = m.get_type()
                if kind == "LOCAL_POSITION_NED":
                    telemetry_offsets.append(now_s - m.time_boot_ms * 1e-3)
                    # Just after a tick: this request waits nearly a whole tick.
                    client.send(client.mav.timesync_encode(0, time.monotonic_ns()))
                elif kind == "TIMESYNC" and m.tc1 != 0:
                    mid_s = (m.ts1 * 1e-9 + now_s) / 2.0
                    timesync_offsets.append(mid_s - m.tc1 * 1e-9)
    finally:
        client.close()
        assert sim.stop() == 0, sim.output()[-2000:]
    assert len(timesync_offsets) >= REQUESTS // 2, sim.output()[-2000:]
    # time_boot_ms is whole milliseconds, truncated: up to 1 ms early.
    from_telemetry = min(telemetry_offsets) - 0.0005
    from_timesync = statistics.median(timesync_offsets)
    assert abs(from_timesync - from_telemetry) < AGREE_S, (from_timesync, from_telemetry)
