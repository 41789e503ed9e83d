"""A compiled twin of the lock-step loop, for the 1 kHz reference runs.

The vectorised functions in `estimator` and `controller` are the reference the
follower processes run; at n = 4 each numpy call costs more than its arithmetic,
so 200 000 steps take ~6 s.  This kernel writes the same law as scalar loops and
is compiled by numba when it is installed.  `tests/unit/test_fastloop.py` holds
the two to 1e-9 of each other.
"""

from __future__ import annotations

import functools
import importlib.util
import math
from collections.abc import Callable
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]
TWO_PI = 2.0 * math.pi
MIN_RANGE_M = 1e-9

# numba is optional (without it the numpy engine runs) and imported on first use:
# follower processes import the core too and should not pay for it.
HAVE_NUMBA = importlib.util.find_spec("numba") is not None


def _limited(x: float, exponent: float, gain: float, cap: float) -> float:
    mag = abs(x)
    return math.copysign(min(gain * mag**exponent, cap * mag), x)


def _steps(
    k0: int,
    k1: int,
    dt: float,
    substeps: int,
    cap: float,
    gains: FloatArray,
    tails: IntArray,
    heads: IntArray,
    fractions: FloatArray,
    succ: IntArray,
    angles: FloatArray,
    p_tilde: FloatArray,
    p_tilde_rate: FloatArray,
    phi: FloatArray,
    psi: FloatArray,
    pos: FloatArray,
    est: FloatArray,
    cmd: FloatArray,
) -> None:
    """Advance steps k0..k1-1 in place.

    gains = (k_e, alpha1, k_z, alpha2, k_d, alpha3, rho_d, w_d, the controller's cap,
    the estimator's order); cap is the estimator step's; psi the velocity stage's state.
    """
    n = phi.shape[0]
    k_e, inv_a1, k_z, inv_a2 = gains[0], 1.0 / gains[1], gains[2], 1.0 / gains[3]
    k_d, inv_a3, rho_d, w_d = gains[4], 1.0 / gains[5], gains[6], gains[7]
    rate, vrate = np.zeros((n, 2)), np.zeros((n, 2))
    dt_e, cap_u, second = dt / substeps, gains[8], gains[9] > 1.5
    for k in range(k0, k1):
        r = phi + p_tilde[k]
        _rates(r, psi, p_tilde_rate[k], second, tails, heads, fractions, inv_a1, k_e, cap,
               rate, vrate)
        for i in range(n):
            s = succ[i]
            rel_x, rel_y = pos[k, i, 0] - r[i, 0], pos[k, i, 1] - r[i, 1]
            rho = max(math.hypot(rel_x, rel_y), MIN_RANGE_M)
            ux, uy = rel_x / rho, rel_y / rho
            sx, sy = pos[k, s, 0] - r[i, 0], pos[k, s, 1] - r[i, 1]
            raw = math.atan2(rel_x * sy - rel_y * sx, rel_x * sx + rel_y * sy)
            gap = (raw - angles[i] + math.pi) % TWO_PI - math.pi + angles[i]
            w_z = _limited(rho - rho_d, inv_a2, k_z, cap_u)
            delta = gap / angles[i] - 1.0
            w_t = _limited(delta, inv_a3, k_d, 0.5 * cap_u * rho * angles[i]) + w_d * rho
            cmd[k, i, 0] = -ux * w_z - uy * w_t + rate[i, 0] + p_tilde_rate[k, i, 0]
            cmd[k, i, 1] = -uy * w_z + ux * w_t + rate[i, 1] + p_tilde_rate[k, i, 1]
        est[k] = r
        if k + 1 < pos.shape[0]:
            pos[k + 1] = pos[k] + dt * cmd[k]
            phi += dt_e * rate
            psi += dt_e * vrate
            # Between control steps p~ moves linearly to its next sample.
            for j in range(1, substeps):
                r = phi + p_tilde[k] + (j * dt_e) * p_tilde_rate[k + 1]
                _rates(r, psi, p_tilde_rate[k + 1], second, tails, heads, fractions, inv_a1,
                       k_e, cap, rate, vrate)
                phi += dt_e * rate
                psi += dt_e * vrate


def _consensus(
    r: FloatArray,
    tails: IntArray,
    heads: IntArray,
    fractions: FloatArray,
    inv_a1: float,
    k_e: float,
    cap: float,
    rate: FloatArray,
) -> None:
    """dPhi/dt of every follower into `rate` (cap: the estimator step's)."""
    rate[:, :] = 0.0
    for e in range(tails.shape[0]):
        i, j = tails[e], heads[e]
        for d in range(2):
            rate[i, d] += _limited(r[j, d] - r[i, d], inv_a1, k_e, cap * fractions[e])


def _rates(
    r: FloatArray,
    psi: FloatArray,
    p_tilde_rate: FloatArray,
    second: bool,
    tails: IntArray,
    heads: IntArray,
    fractions: FloatArray,
    inv_a1: float,
    k_e: float,
    cap: float,
    rate: FloatArray,
    vrate: FloatArray,
) -> None:
    """dPhi/dt into `rate` and, at order 2, dPsi/dt into `vrate` (lockstep._Loop._rates):
    the velocity stage agrees on psi + dp~/dt and feeds psi into dPhi/dt."""
    _consensus(r, tails, heads, fractions, inv_a1, k_e, cap, rate)
    if second:
        _consensus(psi + p_tilde_rate, tails, heads, fractions, inv_a1, k_e, cap, vrate)
        rate += psi


StepsFn = Callable[..., None]


@functools.cache
def compiled_steps() -> StepsFn:
    """`_steps` compiled (cached on disk by numba); raises if numba is not installed."""
    if not HAVE_NUMBA:
        raise RuntimeError("numba is not installed")
    from numba import njit

    global _limited, _consensus, _rates  # _steps resolves them as globals: compiled first
    _limited = njit(cache=True)(_limited)
    _consensus = njit(cache=True)(_consensus)
    _rates = njit(cache=True)(_rates)
    return cast(StepsFn, njit(cache=True)(_steps))


def run_steps(k0: int, k1: int, *args: Any) -> None:
    compiled_steps()(k0, k1, *args)
