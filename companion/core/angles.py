"""Angle helpers that work on floats and numpy arrays alike."""

from __future__ import annotations

import math

from .signals import Num

TAU = 2.0 * math.pi


def wrap(angle: Num) -> Num:
    """Wrap an angle (float or array) to (-pi, pi].

    ``pi - ((pi - a) mod 2 pi)``: Python's and numpy's ``%`` both return a result with the sign of
    the divisor, so one expression serves scalars and arrays.
    """
    return math.pi - (math.pi - angle) % TAU
