"""The step-limited sig: every fractional-power term of the paper's law, on one float."""

from __future__ import annotations

import math

# Finite so that cap * 0 stays 0; it binds only below ~1e-17 of error, where the laws agree.
NO_CAP_PER_S = 1e12


def limited_sig(x: float, exponent: float, gain: float, rate_cap_per_s: float) -> float:
    """gain * sig(x)^exponent, its magnitude capped at rate_cap_per_s * |x|.

    sig(x)^a = sign(x) |x|^a is the paper's odd-ratio power.  A law with a < 1 has
    unbounded gain near zero, so an explicit step of dt overshoots zero and settles into
    a 2-cycle (the numerical dithering the paper claims to avoid).  Capping the rate at
    fraction/dt * |x| (`rate_cap`) lets one step remove at most that fraction of the
    error; as dt -> 0 the cap vanishes and the law is the paper's.
    """
    mag = abs(x)
    return math.copysign(min(gain * mag**exponent, rate_cap_per_s * mag), x)


def rate_cap(step_fraction: float, dt_s: float) -> float:
    """The cap of `limited_sig` for a step of dt: `NO_CAP_PER_S` when the fraction is <= 0."""
    return step_fraction / dt_s if step_fraction > 0.0 else NO_CAP_PER_S
