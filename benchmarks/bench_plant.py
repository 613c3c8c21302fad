"""Figures for the bundled MAVLink plant (``sitl-plant``); prints, asserts nothing.

1. Vehicle step cost in-process (timers + guidance + RoverModel step), paper and stock presets.
2. Lockstep: a pymavlink pilot answers every LOCAL_POSITION_NED at once; telemetry ticks per
   wall second and vehicle seconds per wall second, at 20 and 50 Hz telemetry.
3. Paced: CPU the plant process uses at --speedup 1 and 20 with 40 Hz telemetry.

Run: .venv/bin/python benchmarks/bench_plant.py
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from companion.profiles import ardupilot, setpoint
from companion.sim.plant import RoverParams
from sitl_plant.testing import Pilot, PlantProcess
from sitl_plant.vehicle import Vehicle, VehicleConfig


def bench_step(name: str, params: RoverParams, n: int = 200_000) -> None:
    v = Vehicle(VehicleConfig(params=params))
    v.set_mode(ardupilot.PROFILE.mode_number(ardupilot.PROFILE.track_mode))   # GUIDED
    v.arm(True)
    v.setpoint(setpoint.Setpoint(8, 1511, vx=1.0, yaw_rate=0.2))
    t0 = time.perf_counter()
    for i in range(n):
        if i % 20 == 0:
            v.setpoint(setpoint.Setpoint(8, 1511, vx=1.0, yaw_rate=0.2))
        v.step(0.001)
    per = (time.perf_counter() - t0) / n
    print(f"vehicle step ({name}): {per * 1e6:.2f} us  -> {1 / per / 1000:.0f}x real time at 1 ms")


def bench_lockstep(hz: int, ticks: int = 1000) -> None:
    with PlantProcess("--lockstep", "--lockstep-timeout", "1", "--loop-rate", "100") as plant, \
            Pilot(plant.port) as pilot:
        pilot.wait("HEARTBEAT")
        assert pilot.set_rate(32, hz) == 0 and pilot.set_mode(15) == 0 and pilot.arm() == 0
        first = None
        t0 = time.perf_counter()
        for _ in range(ticks):
            m = pilot.wait("LOCAL_POSITION_NED")
            if first is None:
                first, t0 = m, time.perf_counter()
            pilot.speed_turn_rate(1.0, 0.2)
        wall = time.perf_counter() - t0
        vehicle = (m.time_boot_ms - first.time_boot_ms) / 1000.0
        print(f"lockstep {hz} Hz: {(ticks - 1) / wall:.0f} ticks/s, {vehicle / wall:.1f} vehicle s "
              f"per wall s ({ticks} ticks, {plant.stop() and 'rc!=0' or 'rc 0'})")


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def bench_paced(speedup: float, seconds: float = 4.0) -> None:
    with PlantProcess("--speedup", str(speedup)) as plant, Pilot(plant.port) as pilot:
        pilot.wait("HEARTBEAT")
        assert pilot.set_rate(32, 40) == 0 and pilot.set_rate(30, 40) == 0
        c0, t0 = cpu_seconds(plant.proc.pid), time.perf_counter()
        msgs = pilot.collect(("LOCAL_POSITION_NED",), seconds)
        cpu, wall = cpu_seconds(plant.proc.pid) - c0, time.perf_counter() - t0
        span = (msgs[-1].time_boot_ms - msgs[0].time_boot_ms) / 1000.0
        print(f"paced x{speedup:g}: plant CPU {100 * cpu / wall:.1f} % of a core, "
              f"vehicle/wall {span / wall:.2f}")


if __name__ == "__main__":
    bench_step("paper", RoverParams.paper())
    bench_step("stock, accel-limited RK4", RoverParams.stock_rover())
    bench_lockstep(20)
    bench_lockstep(50)
    bench_paced(1)
    bench_paced(20)
