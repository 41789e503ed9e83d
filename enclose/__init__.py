"""enclose as a library: scenarios, lock-step and networked runs, sweeps, run directories.

    import enclose
    wide = enclose.Scenario.load("paper").replace({"pattern.rho_d_m": 10.0})
    lockstep = enclose.simulate(wide, duration_s=30.0)
    networked = enclose.run(wide, duration_s=30.0)
    networked.series[["e1_e_rho_m", "e2_e_rho_m"]].plot()

`enclose.testing` is the pytest plugin (fixtures `enclose_sim`, `enclose_swarm`).
"""

from __future__ import annotations

from enclose.api import replay, run, simulate, sweep
from enclose.results import Run, load_run
from enclose.scenario import Scenario
from enclose_release import VERSION

__version__ = VERSION

__all__ = ["Run", "Scenario", "__version__", "load_run", "replay", "run", "simulate", "sweep"]
