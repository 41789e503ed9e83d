"""Control laws: the interface a law implements, the shipped ones, and the paper's
equations, each written once.

- `interface`: what a law reads, publishes and commands; `shipped`: the laws a
  scenario's `[law]` names (built by agents.loading.law_loader, by name or module);
  `paper`: the paper's law as one of them; `carry`: a follower's estimate kept continuous
  across a membership change.
- The paper's equations, plain scalar Python on floats and plane vectors as complex
  numbers x + iy, without numpy: the paper's law calls them per link and tick as they are
  (a follower must not import numpy: issue 15, <= 50 MB per follower), and the lock-step
  engine (agents.lockstep.kernel) has numba compile the same functions into its loop.
  So they take plain floats, not parameter objects; the frozen dataclasses beside them
  (EstimatorParams, ControlGains) are for Python callers to keep them in.
  - `sig`: the step-limited fractional power every term is built from, and its rate cap;
  - `consensus`: the estimator's consensus flow on a link, and the robust estimator's
    link balance;
  - `velocity_stage`: the second consensus on the targets' mean velocity (order 2);
  - `enclosing`: the enclosing controller (u, z, delta) and the step its spacing term is
    capped for;
  - `target_velocity`: a target's velocity from its timestamped observations.

tests/reference holds the paper's equations written plainly in numpy; the tests compare
these functions with them.
"""
