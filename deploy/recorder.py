"""The swarm's recorder process: bus + ground truth in, MCAP + metrics + figures out.

    python -m deploy.recorder --scenario paper --swarm NAME --out RUN_DIR \
        --connect tcp/127.0.0.1:PORT [--listen tcp/127.0.0.1:PORT]

Declares liveliness token `alive/recorder/0`, publishes `status/recorder/0` about once a
second ("linked", then "running" once the launcher's RunControl "start" is heard), records
every key of the swarm to `RUN_DIR/recording.mcap` and writes `RUN_DIR/progress.json` each
second.  On RunControl "stop", SIGTERM or SIGINT it closes the MCAP and writes series.csv,
metrics.json, run.json and the figures (`enclose report RUN_DIR` redraws them).
Exit 0 on a clean stop with metrics; 1 if the run gave no usable truth (metrics.json then has
an "error" field; the MCAP is kept); 2 on a configuration or transport error at start.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

from agents.errors import EncloseError
from agents.phases import log_phases, mark
from agents.process import add_bus_arguments, load_run_scenario, open_bus, stop_on_signals
from deploy.recording.loop import Recorder

log = logging.getLogger("deploy.recorder")


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m deploy.recorder", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_bus_arguments(parser)
    parser.add_argument("--out", type=Path, required=True, help="run directory")
    parser.add_argument("--index", type=int, default=0, help="recorder index (default 0)")
    parser.add_argument("-v", "--verbose", action="store_true")
    return parser.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    mark("main")
    args = parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(asctime)s %(levelname)s recorder: %(message)s")
    try:
        scenario = load_run_scenario(args)
        with stop_on_signals() as stop, open_bus(args) as bus:
            recorder = Recorder(bus, args.swarm, scenario, args.out, index=args.index)
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
    log.info("outputs in %s", args.out)
    return 0 if ok and recorder.stop_reason != "loop_error" else 1


if __name__ == "__main__":
    sys.exit(main())
