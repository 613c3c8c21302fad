"""Where the plant is on the earth: its EKF origin, its home, its latitude / longitude.

A real autopilot sets its EKF origin at the first good GPS fix (ArduPilot SITL: about 10 s after
boot) and reports it as GPS_GLOBAL_ORIGIN; LOCAL_POSITION_NED is metres from it. Here the origin
is configured (``--origin``, default ArduPilot SITL's own default home) and set ``delay`` vehicle
seconds after boot (``--origin-delay``: until then it is not reported, as on a vehicle without a
fix). Home is where the rover stood at start-up (``--start``), reported as HOME_POSITION with its
local x, y. Latitude / longitude come from the local position with ArduPilot's own conversion
(:mod:`companion.mission.geo`), so the companion's maths and the plant's agree to the 1e-7 degree.
"""

from __future__ import annotations

from dataclasses import dataclass

from companion.mission import geo

# ArduPilot SITL's default home (Tools/autotest/locations.txt, CMAC): also the planned home of
# missions/example_rover.plan, so that plan flies from the plant's start by default.
CMAC = (-35.363261, 149.165230, 584.0)


@dataclass(frozen=True)
class OriginConfig:
    lat: float = CMAC[0]
    lon: float = CMAC[1]
    alt: float = CMAC[2]      # m above mean sea level
    delay: float = 0.0        # vehicle s after boot before the origin is set (a GPS fix)


class Earth:
    def __init__(self, config: OriginConfig, start_xy: tuple[float, float]):
        self.config = config
        self._delay_us = int(round(config.delay * 1e6))
        self.home_xy = (float(start_xy[0]), float(start_xy[1]))

    @property
    def origin(self) -> tuple[float, float]:
        return self.config.lat, self.config.lon

    def origin_set(self, t_us: int) -> bool:
        return t_us >= self._delay_us

    def latlon(self, x: float, y: float) -> tuple[float, float]:
        """Degrees of the local point (x north, y east) m from the origin."""
        return geo.latlon_from_ne(x, y, self.origin)

    def home(self) -> tuple[float, float]:
        return self.latlon(*self.home_xy)


def e7(degrees: float) -> int:
    return geo.to_e7(degrees)
