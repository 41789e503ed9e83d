"""One run on this machine: what the launcher was asked, its secrets, ports and faults, what it
watches, and how the run ends."""
