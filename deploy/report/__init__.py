"""The end of a run: its metrics, verdict, figures and what it cost, read from the run
directory."""
