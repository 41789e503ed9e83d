"""The shell every swarm process lives in: its command line, bus, start-up phases, lifeline and
fixed-rate loop."""
