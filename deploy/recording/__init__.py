"""The recorder's parts; `python -m deploy.recording.recorder` wires them into one process.

Nothing the recorder keeps in memory grows with the length of the run: what it needs at
the end goes to disk as it arrives, and the end reads it back chunk by chunk.

- `assembler.RunAssembler`: decoded messages in; truth and states spilled to disk
  (`spill.RowSpill`), per-follower counters (states, sequence gaps) and the last seconds
  in memory for live progress.
- `chunks.Assembly`: the run on the truth grid, one chunk of samples at a time, with the
  counters that qualify it (state age at use, first-state fills).
- `intake.Intake`: every sample on a known key recorded as it arrived; follower states and
  observations recorded from their wire arrays and decoded later, a bounded batch at a
  time, the newest at the view's rate.
- `mcap_log.McapLog`: streaming, chunked MCAP file, one JSON channel per key, JSON schemas
  generated from the message dataclasses (opens in Foxglove and PlotJuggler); its chunk
  indexes wait on disk for the summary (`mcap_fast`).
- `resume`: a recording read back.
- `progress`, `recorder_report`: the live `progress.json` for the launcher (atomic writes),
  metrics.json's recorder share and the recorder's status counters.
- `outputs`: the end of a run: `metrics.json`, `run.json`, `series.csv`, `series.parquet`
  and figures through `deploy.report.run_report.write_run_outputs` -- the code
  `enclose simulate` uses.
- `links`: metrics.json "links" -- per link (`"f0->f2"`, `"sensor->f2"`, 0-based) the
  delivered ratio and age at delivery, from the followers' final ("done") counters, which
  the loop waits for (at most ~2 s) after the stop.
- `deploy.report.link_history`: links.csv, streamed to disk as the followers' counters
  arrive (its format is the run directory's, read back by the report).
- `loop.Recorder`: the process's single loop over a `Bus`.
"""
