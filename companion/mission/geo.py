"""Latitude/longitude <-> local north/east, exactly as ArduPilot converts them.

ArduPilot (libraries/AP_Common/Location.cpp, ``get_vector_xy_from_origin_NE`` and
``get_distance_NE``, 4.1 and later) works on integer 1e-7 degree units and a flat earth around
the EKF origin:

    north = (lat - lat0) * 0.011131884502145034
    east  = diff_longitude(lon, lon0) * 0.011131884502145034 * longitude_scale((lat + lat0) / 2)

with ``longitude_scale(l) = cos(l * 1e-7 deg)`` clamped to [0.01, 1], the mean latitude taken in
integer arithmetic (C division, truncating towards zero) and ``diff_longitude`` wrapping across
the antimeridian. The constant is 1e-7 * pi/180 * 6378100 m. LOCAL_POSITION_NED is relative to the
same EKF origin, so mission points converted here line up with what the vehicle reports.
Degrees are rounded to the nearest 1e-7 degree first, as a MISSION_ITEM_INT carries them.
"""

from __future__ import annotations

import math

LOCATION_SCALING_FACTOR = 0.011131884502145034   # m per 1e-7 degree at the equator
LOCATION_SCALING_FACTOR_INV = 89.83204953368922  # 1e-7 degrees per metre


def to_e7(degrees: float) -> int:
    """Degrees to ArduPilot's integer 1e-7 degree units (nearest, as MISSION_ITEM_INT holds them)."""
    return int(round(degrees * 1e7))


def longitude_scale(lat_e7: int) -> float:
    """cos(latitude), clamped to [0.01, 1] as ArduPilot does near the poles."""
    return min(1.0, max(0.01, math.cos(lat_e7 * 1e-7 * math.pi / 180.0)))


def diff_longitude(lon1_e7: int, lon2_e7: int) -> int:
    """lon1 - lon2 in 1e-7 degrees, wrapped into [-180, 180] degrees."""
    d = lon1_e7 - lon2_e7
    if d > 1_800_000_000:
        d -= 3_600_000_000
    elif d < -1_800_000_000:
        d += 3_600_000_000
    return d


def _mean_lat_e7(a: int, b: int) -> int:
    """(a + b) / 2 with C integer division (truncates towards zero, unlike Python's //)."""
    s = a + b
    return -((-s) // 2) if s < 0 else s // 2


def ne_from_latlon(lat: float, lon: float, origin: tuple[float, float]) -> tuple[float, float]:
    """(north, east) in metres of the point (lat, lon) degrees from ``origin`` = (lat0, lon0)."""
    lat_e7, lon_e7 = to_e7(lat), to_e7(lon)
    lat0_e7, lon0_e7 = to_e7(origin[0]), to_e7(origin[1])
    north = (lat_e7 - lat0_e7) * LOCATION_SCALING_FACTOR
    east = (diff_longitude(lon_e7, lon0_e7) * LOCATION_SCALING_FACTOR
            * longitude_scale(_mean_lat_e7(lat_e7, lat0_e7)))
    return north, east


def latlon_from_ne(north: float, east: float, origin: tuple[float, float]) -> tuple[float, float]:
    """The inverse of :func:`ne_from_latlon` (to within the 1e-7 degree grid, about 1 cm)."""
    lat0_e7, lon0_e7 = to_e7(origin[0]), to_e7(origin[1])
    lat_e7 = lat0_e7 + round(north * LOCATION_SCALING_FACTOR_INV)
    scale = longitude_scale(_mean_lat_e7(lat_e7, lat0_e7))
    lon_e7 = lon0_e7 + round(east * LOCATION_SCALING_FACTOR_INV / scale)
    if lon_e7 > 1_800_000_000:
        lon_e7 -= 3_600_000_000
    elif lon_e7 < -1_800_000_000:
        lon_e7 += 3_600_000_000
    return lat_e7 * 1e-7, lon_e7 * 1e-7


def check_latlon(lat: float, lon: float) -> str | None:
    """Why (lat, lon) is not a usable position, or None if it is."""
    if not (math.isfinite(lat) and math.isfinite(lon)):
        return "is not a finite latitude/longitude"
    if not -90.0 <= lat <= 90.0:
        return f"latitude {lat!r} is outside [-90, 90]"
    if not -180.0 <= lon <= 180.0:
        return f"longitude {lon!r} is outside [-180, 180]"
    return None
