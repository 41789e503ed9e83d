"""The lock-step loop's steps, on the law's one source (agents.law), compiled by numba.

`simulate_lockstep` hands a whole run's arrays to `run_steps`, plane vectors as complex
x + iy, and it advances them in place.  The loop calls the law's own functions, wired to
the gains as the follower's law wires them (agents.law.paper_wiring): with numba
installed they are compiled into it (`compiled_steps`: cached on disk, and compiled again
when any of their sources changes); without, the same code runs as plain Python, correct
and about a hundred times slower.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import inspect
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents.law.consensus import EstimatorParams, link_flow
from agents.law.enclosing import ControlGains, enclosing_control, spacing_step_s
from agents.law.paper_wiring import command, estimator_flow, gains_of, second_order
from agents.law.sig import limited_sig, rate_cap
from agents.law.velocity_stage import fed_flow, lap_velocity

ComplexArray = NDArray[np.complex128]
FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]
StepsFn = Callable[..., None]

# numba is optional and imported on first use: follower processes import the law too
# and must not pay for it.
HAVE_NUMBA = importlib.util.find_spec("numba") is not None


def _steps(k0: int, k1: int, dt: float, substeps: int, law: FloatArray, tails: IntArray,
           heads: IntArray, fractions: FloatArray, succ: IntArray, angles: FloatArray,
           p_tilde: ComplexArray, p_tilde_rate: ComplexArray, phi: ComplexArray,
           psi: ComplexArray, pos: ComplexArray, est: ComplexArray, cmd: ComplexArray,
           wind: ComplexArray, leak: float, gps: ComplexArray) -> None:
    """Advance steps k0..k1-1 in place (`law`: `law_vector`; psi: the velocity stage's state,
    zero at order 1; `wind`: each step's wind per follower, of which the vehicle lets `leak`
    through, or no rows: still air; `gps`: the error of each step's reported positions, the
    law's view of them, or no rows: exact).  Between control steps the
    estimator takes `substeps` steps, p~ moving linearly to its next sample."""
    n = phi.shape[0]
    r = np.zeros(n, np.complex128)
    rate, vrate, rv = np.zeros_like(r), np.zeros_like(r), np.zeros_like(r)
    dt_e = dt / substeps
    for k in range(k0, k1):
        for i in range(n):
            r[i] = phi[i] + p_tilde[k, i]
        _rates(r, psi, p_tilde_rate[k], law, tails, heads, fractions, rate, vrate, rv)
        _commands(k, dt, law, succ, angles, r, rate, p_tilde_rate[k], pos, cmd, gps)
        est[k, :] = r
        if k + 1 < pos.shape[0]:
            for i in range(n):
                pos[k + 1, i] = pos[k, i] + dt * cmd[k, i]
                phi[i] += dt_e * rate[i]
                psi[i] += dt_e * vrate[i]
            if wind.shape[0] > 0:
                for i in range(n):
                    pos[k + 1, i] += dt * leak * wind[k, i]
            for j in range(1, substeps):
                for i in range(n):
                    r[i] = phi[i] + p_tilde[k, i] + (j * dt_e) * p_tilde_rate[k + 1, i]
                _rates(r, psi, p_tilde_rate[k + 1], law, tails, heads, fractions, rate, vrate,
                       rv)
                for i in range(n):
                    phi[i] += dt_e * rate[i]
                    psi[i] += dt_e * vrate[i]


def _commands(k: int, dt: float, law: FloatArray, succ: IntArray, angles: FloatArray,
              r: ComplexArray, rate: ComplexArray, p_tilde_rate: ComplexArray,
              pos: ComplexArray, cmd: ComplexArray, gps: ComplexArray) -> None:
    """Every follower's command at step k into cmd[k] (dr_i/dt = dPhi_i/dt + dp~_i/dt;
    lock-step data is never old, so the successor's age is 0), from the positions as the
    vehicles report them."""
    for i in range(r.shape[0]):
        own, ahead = pos[k, i], pos[k, succ[i]]
        if gps.shape[0] > 0:
            own += gps[k, i]
            ahead += gps[k, succ[i]]
        cmd[k, i] = command(own, ahead, r[i], rate[i] + p_tilde_rate[i], angles[i], law,
                            dt, 0.0)


def _rates(r: ComplexArray, psi: ComplexArray, p_tilde_rate: ComplexArray, law: FloatArray,
           tails: IntArray, heads: IntArray, fractions: FloatArray, rate: ComplexArray,
           vrate: ComplexArray, rv: ComplexArray) -> None:
    """dPhi/dt into `rate` and, at order 2, dPsi/dt into `vrate` (rv: scratch for rv_i)."""
    _consensus(r, law, tails, heads, fractions, rate)
    if second_order(law):
        for i in range(r.shape[0]):
            rv[i] = lap_velocity(psi[i], p_tilde_rate[i])
        _consensus(rv, law, tails, heads, fractions, vrate)
        for i in range(r.shape[0]):
            rate[i] = fed_flow(rate[i], psi[i])


def _consensus(r: ComplexArray, law: FloatArray, tails: IntArray, heads: IntArray,
               fractions: FloatArray, out: ComplexArray) -> None:
    """Every follower's sum of link flows of `r` into `out`."""
    out[:] = 0j
    for e in range(tails.shape[0]):
        i = tails[e]
        out[i] += estimator_flow(r[i], r[heads[e]], law, fractions[e])


def law_vector(estimator: EstimatorParams, control: ControlGains,
               est_period_s: float) -> FloatArray:
    """The law's gains (agents.law.paper_wiring.gains_of) as `_steps` reads them: one float
    array, one compiled signature."""
    return np.array(gains_of(estimator, control, est_period_s), dtype=np.float64)


# Every function `_steps` calls, directly or not: numba compiles a call to a plain Python
# function only once it is registered (`compiled_steps`), and the cache digests their files.
_LAW = (limited_sig, rate_cap, spacing_step_s, link_flow, lap_velocity, fed_flow,
        enclosing_control, second_order, estimator_flow, command)
_LOOP = (_consensus, _rates, _commands)


def sources_digest() -> str:
    """A digest of every source file the compiled loop is made of."""
    files = sorted({inspect.getfile(fn) for fn in (*_LAW, *_LOOP, _steps)})
    digest = hashlib.sha256()
    for name in files:
        digest.update(Path(name).read_bytes())
    return digest.hexdigest()


@functools.cache
def compiled_steps() -> StepsFn:
    """`_steps` compiled with the law, cached on disk; raises if numba is not installed.

    register_jitable lets numba compile a call to a plain Python function without
    changing the function: the follower processes keep calling the very same objects."""
    if not HAVE_NUMBA:
        raise RuntimeError("numba is not installed")
    from numba import njit
    from numba.extending import register_jitable

    for fn in (*_LAW, *_LOOP):
        register_jitable(fn)
    steps = njit(cache=True)(_steps)
    # numba keys its disk cache on the stamp of _steps' own file only: a change to the
    # law's files would run the old law from the cache.  Key it on all of them.
    cache_file = getattr(getattr(steps, "_cache", None), "_cache_file", None)
    if cache_file is None or not hasattr(cache_file, "_source_stamp"):
        return njit(cache=False)(_steps)  # another numba: compiled at every start, still right
    cache_file._source_stamp = (cache_file._source_stamp, sources_digest())
    return steps


def run_steps(k0: int, k1: int, compiled: bool, *args: Any) -> None:
    """`_steps` compiled (numba) or as plain Python."""
    (compiled_steps() if compiled else _steps)(k0, k1, *args)
