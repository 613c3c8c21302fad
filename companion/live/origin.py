"""Where the vehicle's local frame lies on the earth, and the geodetic missions placed there.

LOCAL_POSITION_NED, which the loop tracks on, is metres north / east of the vehicle's EKF origin:
ArduPilot sets it at the first good GPS fix (on SITL about 10 s after boot), wherever the rover
was then. A mission drawn by latitude / longitude (a QGroundControl ``.plan``, a ``.waypoints``
file, a TOML ``frame = "geodetic"``) only flies where it was drawn when its points are converted
around that very origin, so it is read from the vehicle after connecting:

* ``GPS_GLOBAL_ORIGIN`` (id 49), asked for with ``MAV_CMD_REQUEST_MESSAGE`` once a second: the
  origin itself;
* ``HOME_POSITION`` (id 242), asked for alongside: home's latitude / longitude and its local
  x, y, so origin = home moved back by (x, y) (:func:`companion.mission.geo.latlon_from_ne`).
  Used only when GPS_GLOBAL_ORIGIN has not come ``HOME_GRACE`` s after it (an autopilot that
  does not answer for 49).

Neither comes while the origin is not set (no GPS fix yet): the caller waits up to a timeout.
A user's ``--origin`` is checked against the vehicle's (:data:`ORIGIN_TOLERANCE`) and used as
given only when the vehicle tells none.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..errors import UserError
from ..mission import geo

GPS_GLOBAL_ORIGIN = 49
HOME_POSITION = 242
MAV_CMD_REQUEST_MESSAGE = 512
ASK_EVERY = 1.0          # wall s between requests while waiting
HOME_GRACE = 3.0         # wall s to still wait for GPS_GLOBAL_ORIGIN once HOME_POSITION came
ORIGIN_TOLERANCE = 5.0   # m: --origin must lie this close to the vehicle's EKF origin
SAY_WAITING = 2.0        # wall s: say that we wait for the origin once it takes this long


@dataclass(frozen=True)
class EkfOrigin:
    lat: float       # degrees
    lon: float
    alt: float       # m above mean sea level (information only: the loop is 2-D)
    source: str      # "GPS_GLOBAL_ORIGIN", "HOME_POSITION" or "--origin"

    @property
    def latlon(self) -> tuple[float, float]:
        return self.lat, self.lon

    def as_dict(self) -> dict[str, Any]:
        return {"lat": self.lat, "lon": self.lon,
                "alt": self.alt if math.isfinite(self.alt) else None, "source": self.source}


def distance_m(a: tuple[float, float], b: tuple[float, float]) -> float:
    """Horizontal metres between two (lat, lon), as ArduPilot measures them."""
    return math.hypot(*geo.ne_from_latlon(a[0], a[1], b))


def from_message(msg: Any) -> EkfOrigin | None:
    """The origin a GPS_GLOBAL_ORIGIN or HOME_POSITION says, or None (not one of them, or
    nonsense: not finite, off the earth, or 0, 0, which autopilots send for "not set")."""
    kind = msg.get_type()
    if kind not in ("GPS_GLOBAL_ORIGIN", "HOME_POSITION"):
        return None
    lat, lon, alt = msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3
    if (msg.latitude, msg.longitude) == (0, 0) or geo.check_latlon(lat, lon) is not None:
        return None
    if kind == "HOME_POSITION":
        x, y, z = float(msg.x), float(msg.y), float(msg.z)
        if not all(math.isfinite(v) and abs(v) < 1e6 for v in (x, y, z)):
            return None
        lat, lon = geo.latlon_from_ne(-x, -y, (lat, lon))   # home is at (x, y) of the origin
        alt += z                                              # z is down
    return EkfOrigin(lat, lon, alt, kind)


def read_origin(link: Any, timeout: float,
                should_stop: Callable[[], bool] = lambda: False,
                log: Callable[[str], None] = lambda text: None) -> EkfOrigin | None:
    """The vehicle's EKF origin, asking once a second, or None after ``timeout`` wall s.

    Other messages read meanwhile are dropped: only for set-up, before the control loop.
    """
    start = time.monotonic()
    deadline = start + timeout
    next_ask = start
    home: EkfOrigin | None = None
    home_at = 0.0
    said_waiting = False
    while (now := time.monotonic()) < deadline and not should_stop():
        if home is not None and now - home_at >= HOME_GRACE:
            return home
        if not said_waiting and now - start >= SAY_WAITING:
            said_waiting = True
            log(f"waiting for the vehicle's EKF origin (no GPS fix yet?), up to {timeout:g} s")
        if now >= next_ask:
            for msg_id in (GPS_GLOBAL_ORIGIN, HOME_POSITION):
                link.command(MAV_CMD_REQUEST_MESSAGE, msg_id)
            next_ask = now + ASK_EVERY
        msg = link.recv()
        if msg is None:
            link.wait(min(0.05, max(0.0, deadline - now)))
            continue
        if not link.is_vehicle(msg):
            continue
        origin = from_message(msg)
        if origin is None:
            continue
        if origin.source == "GPS_GLOBAL_ORIGIN":
            return origin
        if home is None:
            home, home_at = origin, now
    if should_stop():
        raise KeyboardInterrupt
    return home


def place(mission: Any, link: Any, override: tuple[float, float] | None, timeout: float,
          log: Callable[[str], None] = lambda text: None,
          should_stop: Callable[[], bool] = lambda: False) -> tuple[Any, EkfOrigin]:
    """``mission`` (geodetic) placed around the vehicle's EKF origin, and that origin.

    UserError (nothing has moved yet) when the vehicle tells no origin within ``timeout`` and
    there is no ``override``, or when ``override`` is more than :data:`ORIGIN_TOLERANCE` from
    the vehicle's.
    """
    told = read_origin(link, timeout, should_stop, log)
    if told is None:
        if override is None:
            raise UserError(
                f"the vehicle reported no EKF origin (GPS_GLOBAL_ORIGIN / HOME_POSITION) within "
                f"{timeout:g} s, and '{mission.name}' is placed by latitude / longitude: wait for "
                "its GPS fix (--origin-timeout S to wait longer) or give --origin LAT,LON")
        origin = EkfOrigin(override[0], override[1], math.nan, "--origin")
        log(f"the vehicle reported no EKF origin within {timeout:g} s: using --origin "
            f"{override[0]:.7f},{override[1]:.7f} unchecked")
    else:
        if override is not None:
            off = distance_m(override, told.latlon)
            if off > ORIGIN_TOLERANCE:
                raise UserError(
                    f"--origin {override[0]:.7f},{override[1]:.7f} is {off:.1f} m from the "
                    f"vehicle's EKF origin {told.lat:.7f},{told.lon:.7f} ({told.source}), more "
                    f"than {ORIGIN_TOLERANCE:g} m: leave --origin out to use the vehicle's")
            log(f"--origin agrees with the vehicle's EKF origin within {off:.2f} m")
        origin = told
    placed = mission.at_origin(origin.latlon)
    log(f"EKF origin {origin.lat:.7f}, {origin.lon:.7f} ({origin.source}): "
        f"'{placed.name}' placed around it")
    return placed, origin
