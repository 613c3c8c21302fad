"""The speed channel at the ellipse's own frequency: the vehicle against its identified model.

The paper's ellipse asks a speed that varies at twice its frequency (2 f_r: 1.0 rad/s at
0.08 Hz). For each flight log this fits one sinusoid at 2 f_r to the second half's speed
setpoints, to the speed the vehicle flew and to the speed the vehicle file's model answers to
the same setpoints (:func:`companion.ident.fit.simulate`), and prints the gain and the lag (s)
of vehicle and model there, with the model's RMS over the whole log
(:func:`companion.ident.fit.rms`). A model can explain a manoeuvre's steps to a few cm/s and
still lag the vehicle by a tenth of a second at the frequency a tracking flight lives at.

    python benchmarks/channel_response.py VEHICLE.toml LOG.tlog [LOG.tlog ...] [--f-r 0.04,0.08]

Prints figures, asserts nothing.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from companion.ident import fit
from companion.ident.data import read_series
from companion.sim import vehicle_file

MIN_AMPLITUDE = 0.05      # m/s: a smaller setpoint swing at 2 f_r says nothing about the gain


def phasor(t: np.ndarray, x: np.ndarray, omega: float) -> complex:
    """The complex amplitude of ``x``'s component at ``omega`` (least squares, with a mean)."""
    basis = np.column_stack([np.cos(omega * t), np.sin(omega * t), np.ones_like(t)])
    c, *_ = np.linalg.lstsq(basis, x, rcond=None)
    return complex(c[0], -c[1])


def response(setpoint: complex, output: complex, omega: float) -> tuple[float, float]:
    """(gain, lag in s) from the setpoint's phasor to the output's."""
    ratio = output / setpoint
    return abs(ratio), -math.atan2(ratio.imag, ratio.real) / omega


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("vehicle")
    ap.add_argument("logs", nargs="+")
    ap.add_argument("--f-r", default="0.04,0.08", help="ellipse frequencies, Hz")
    args = ap.parse_args()
    params = vehicle_file.load(args.vehicle).params
    print("| log | model RMS m/s | f_r | setpoint swing m/s | vehicle gain, lag | model gain, lag |")
    print("|---|---|---|---|---|---|")
    for log in args.logs:
        series, _ = read_series(log)
        speed_rms, _ = fit.rms(params, series)
        model, _ = fit.simulate(params, series)
        t = series.t
        late = t > t[0] + 0.5 * (t[-1] - t[0])
        for f_r in (float(x) for x in args.f_r.split(",")):
            omega = 2.0 * math.pi * 2.0 * f_r
            sp = phasor(t[late], series.speed_cmd[late], omega)
            if abs(sp) < MIN_AMPLITUDE:
                continue
            vg, vl = response(sp, phasor(t[late], series.speed[late], omega), omega)
            mg, ml = response(sp, phasor(t[late], model[late], omega), omega)
            print(f"| {Path(log).name} | {speed_rms:.3f} | {f_r:g} | {abs(sp):.3f} | "
                  f"{vg:.3f}, {vl:.3f} s | {mg:.3f}, {ml:.3f} s |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
