"""The simulator's weather: wind on the airframes and noise on what they report.

Built only when the scenario has `[wind]` or GPS noise (`weather_of`): without them the
simulator steps exactly as before, with no draw and no work per tick.
"""

from __future__ import annotations

from agents.scenario.model import Scenario
from agents.scenario.weather_tables import WindConfig
from agents.weather.gps import GpsNoise
from agents.weather.gusts import WindField, wind_ned
from agents.weather.windows import WindSchedule, window_strengths
from sim_backend import kinematics
from sim_backend.kinematics import FloatArray


class SimWeather:
    """Steps the fleet in its wind and gives each vehicle's reported position."""

    def __init__(self, scenario: Scenario, n_vehicles: int,
                 windows: tuple[float, ...] = ()) -> None:
        wind = scenario.wind or (WindConfig() if windows else None)
        self.wind = None if wind is None else WindField(wind, n_vehicles)
        self.drag_1_s = 0.0 if wind is None else wind.drag_1_s
        # Gust windows on the timeline, opened and closed by the launcher's signals.
        self.schedule = None if wind is None or not windows else WindSchedule(
            windows, wind.gust_std_m_s)
        vehicle = scenario.vehicle
        self.gps = GpsNoise(vehicle, n_vehicles) if vehicle.gps_noisy else None
        self.air_enu = None if self.wind is None else self.wind.velocity()

    def step(self, state: kinematics.FleetState, cmd: kinematics.FleetCommand,
             p: kinematics.ModelParams, dt_s: float) -> kinematics.FleetState:
        if self.wind is None:
            new = kinematics.step(state, cmd, p, dt_s)
        else:
            if self.schedule is not None:
                self.wind.std_m_s = self.schedule.std_m_s
            self.air_enu = self.wind.advance(dt_s)
            new = kinematics.step(state, cmd, p, dt_s, wind_ned(self.air_enu), self.drag_1_s)
        if self.gps is not None:
            self.gps.advance(dt_s)
        return new

    def reported_ned(self, pos_ned_m: FloatArray) -> FloatArray:
        """Positions as the vehicles' telemetry reports them."""
        if self.gps is None:
            return pos_ned_m
        out = pos_ned_m.copy()
        out[:, 0] += self.gps.error[:, 1]
        out[:, 1] += self.gps.error[:, 0]
        return out


def weather_of(scenario: Scenario, n_vehicles: int,
               windows: tuple[float, ...] | None = None) -> SimWeather | None:
    """The run's weather, or None when it has none (the simulator then is as it was).
    `windows`: the gust windows' strengths the launcher will open, in time order (None:
    the scenario's own `[[faults]]`)."""
    strengths = window_strengths(scenario.faults) if windows is None else windows
    if scenario.wind is None and not strengths and not scenario.vehicle.gps_noisy:
        return None
    return SimWeather(scenario, n_vehicles, strengths)
