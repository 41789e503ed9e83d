"""The recorder's parts; `python -m deploy.recorder` wires them into one process.

- `assembler.RunAssembler`: pure; decoded messages in, a `RunSeries` on the truth grid out,
  plus per-follower counters (states, sequence gaps, state age at use, first-state fills).
- `mcap_log.McapLog`: streaming, chunked MCAP file, one JSON channel per key, JSON schemas
  generated from the message dataclasses (opens in Foxglove and PlotJuggler).
- `progress`: the live `progress.json` for the launcher (atomic writes).
- `outputs`: the end of a run: `metrics.json`, `run.json`, `series.csv` and figures through
  `deploy.report.write_run_outputs` -- the code `enclose simulate` uses.
- `links`: metrics.json "links" -- per link (`"f0->f2"`, `"sensor->f2"`, 0-based) the
  delivered ratio and age at delivery, from the followers' final ("done") counters, which
  the loop waits for (at most ~2 s) after the stop.
- `loop.Recorder`: the process's single loop over a `Bus`.
"""
