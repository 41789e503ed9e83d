"""The float twins of agents.core.geometry's primitives, without numpy.

The networked follower computes one follower's law on Python floats and complex numbers
(numpy's per-call cost is most of a 2-vector's), and its process must not import numpy
at all (issue 15: <= 50 MB per follower); tests/unit/test_scalar_twins.py pins these to
the array versions.
"""

from __future__ import annotations

import math

TWO_PI = 2.0 * math.pi
# Finite so that cap * 0 stays 0; it binds only below ~1e-17 of error, where the laws agree.
NO_CAP_PER_S = 1e12


def limited_sig_one(x: float, exponent: float, gain: float, rate_cap_per_s: float) -> float:
    """`limited_sig` of one float (the networked follower's plane vectors are complex,
    their components plain floats: numpy's per-call cost is most of a 2-vector's)."""
    mag = abs(x)
    return math.copysign(min(gain * mag**exponent, rate_cap_per_s * mag), x)


def rate_cap(step_fraction: float, dt_s: float) -> float:
    """The cap of `limited_sig` for a step of dt: `NO_CAP_PER_S` when the fraction is <= 0."""
    return step_fraction / dt_s if step_fraction > 0.0 else NO_CAP_PER_S
