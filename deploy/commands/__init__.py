"""The `enclose` subcommands that start things: `simulate` (lock-step), `run` (the
networked swarm), `sim` (the vehicle simulator alone), `host` (one host's share of a
multi-host run).  `deploy.cli` wires them."""
