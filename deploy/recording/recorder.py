"""The swarm's recorder process: bus + ground truth in, MCAP + metrics + figures out.

    python -m deploy.recording.recorder --scenario paper --swarm NAME --out RUN_DIR \
        --connect tcp/127.0.0.1:PORT [--listen tcp/127.0.0.1:PORT] [--live-port 8765]

Declares liveliness token `alive/recorder/0`, publishes `status/recorder/0` about once a
second ("linked", then "running" once the launcher's RunControl "start" is heard), records
every key of the swarm to `RUN_DIR/recording.mcap` and writes `RUN_DIR/progress.json` each
second.  With --live-port it serves the live view (Foxglove WebSocket, deploy.recording.
live_server) on --live-host (127.0.0.1) at that port or the next free one, and names its URL
in progress.json ("live_url"); the view's channels are in the MCAP either way.  On
RunControl "stop", SIGTERM or SIGINT it closes the MCAP and writes series.csv, metrics.json,
run.json and the figures (`enclose report RUN_DIR` redraws them).
Exit 0 on a clean stop with metrics; 1 if the run gave no usable truth (metrics.json then has
an "error" field; the MCAP is kept); 2 on a configuration or transport error at start.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from agents.shell.lifeline import die_with_launcher
from agents.shell.phases import log_phases, mark
from agents.shell.process import (
    apply_agent_sched,
    load_run_scenario,
    open_bus,
    profiled,
    stop_on_signals,
)
from agents.shell.process_options import BusOptions, add_bus_arguments
from deploy.recording.live_defaults import DEFAULT_HOST
from deploy.recording.live_server import LiveServer
from deploy.recording.loop import Recorder
from errors import EncloseError

log = logging.getLogger("deploy.recording.recorder")


@dataclass(frozen=True)
class RecorderOptions:
    """The recorder process's command line."""

    bus: BusOptions
    out: Path
    index: int = 0
    live_port: int | None = None  # None: no live view; 0: any free port
    live_host: str = DEFAULT_HOST
    record_sensor: bool = True
    verbose: bool = False
    figures: bool = True  # drawn at the end

    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> RecorderOptions:
        return cls(BusOptions.from_namespace(args), args.out, args.index, args.live_port,
                   args.live_host, args.record_sensor, args.verbose, args.figures)


def parse_options(argv: Sequence[str] | None) -> RecorderOptions:
    parser = argparse.ArgumentParser(prog="python -m deploy.recording.recorder",
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_bus_arguments(parser)
    parser.add_argument("--out", type=Path, required=True, help="run directory")
    parser.add_argument("--index", type=int, default=0, help="recorder index (default 0)")
    parser.add_argument("--live-port", type=int, default=None, metavar="PORT",
                        help="serve the live view from this port (or the next free one); "
                        "0: any free port; default: no live server")
    parser.add_argument("--live-host", default=DEFAULT_HOST,
                        help="address the live view listens on (default 127.0.0.1: this "
                        "machine only; the view has no authentication)")
    parser.add_argument("--no-sensor", dest="record_sensor", action="store_false",
                        help="do not record the target observations (the launcher's choice "
                        "when the sensor is noiseless: the truth holds the same positions)")
    parser.add_argument("--no-figures", dest="figures", action="store_false",
                        help="no figures at the end (`enclose report RUN` draws them later)")
    parser.add_argument("-v", "--verbose", action="store_true")
    return RecorderOptions.from_namespace(parser.parse_args(argv))


def start_live(opts: RecorderOptions) -> LiveServer | None:
    """The live server, or None: asked for none, or none could start (the recording matters
    more than the view, so that is a warning, not an exit)."""
    if opts.live_port is None:
        return None
    try:
        live = LiveServer(opts.live_host, opts.live_port)
    except EncloseError as exc:
        log.warning("no live view: %s", exc)
        return None
    log.info("live view on %s (Foxglove: Open connection -> %s)", live.url, live.url)
    return live


def main(argv: Sequence[str] | None = None) -> int:
    die_with_launcher()  # agents.shell.lifeline
    mark("main")
    opts = parse_options(argv)
    logging.basicConfig(level=logging.DEBUG if opts.verbose else logging.INFO,
                        format="%(asctime)s %(levelname)s recorder: %(message)s")
    return profiled(_record, opts, "recorder")


def _record(opts: RecorderOptions) -> int:
    try:
        scenario = load_run_scenario(opts.bus)
        apply_agent_sched(scenario.network, vehicle_agent=False)
        with stop_on_signals() as stop, open_bus(opts.bus, scenario.network) as bus:
            live = start_live(opts)
            recorder = Recorder(bus, opts.bus.swarm, scenario, opts.out, index=opts.index,
                                live=live, record_sensor=opts.record_sensor,
                                figures=opts.figures)
            mark("linked")  # its liveliness token is declared
            log_phases("recorder")
            try:
                recorder.run(lambda: stop.raised)
            except Exception:  # a bug in the loop must still leave a finished MCAP behind
                log.exception("recorder loop failed")
                recorder.stop_reason = "loop_error"
            ok = recorder.finish()
    except EncloseError as exc:
        log.error("%s: %s", type(exc).__name__, exc)
        return 2
    log.info("outputs in %s", opts.out)
    return 0 if ok and recorder.stop_reason != "loop_error" else 1


if __name__ == "__main__":
    sys.exit(main())
