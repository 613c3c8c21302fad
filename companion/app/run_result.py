"""How ``companion run`` and ``demo`` print a flight's result: text lines, or one JSON object."""

from __future__ import annotations

import json


def print_result(result, as_json: bool, extra: dict | None = None) -> None:
    d = result.as_dict()
    if extra:
        d.update(extra)
    if as_json:
        print(json.dumps(d), flush=True)
        return
    def ms(x):
        return "n/a" if x is None else f"{x:.3f} ms"
    rejected = {k: v for k, v in d["telemetry_rejected"].items() if v}
    lines = [
        f"result      {d['reason']} (exit {d['exit_code']})",
        f"mission     {d['mission']}: {d['duration_s']:.2f} s tracked",
        f"tracking    f_cost {d['f_cost']:.4f}, steady RMS "
        + ("n/a" if d['steady_rms'] is None else f"{d['steady_rms']:.4f} m"),
        f"loop        {d['cycles']} cycles at "
        + ("n/a" if d['loop_rate_hz'] is None else f"{d['loop_rate_hz']:.1f} Hz")
        + f" (asked {d['rate_requested_hz']:g} Hz, vehicle accepted "
        + (f"{d['rate_accepted_hz']:g} Hz)" if d['rate_accepted_hz'] else "nothing)"),
        f"latency     p50 {ms(d['latency_p50_ms'])}, p99 {ms(d['latency_p99_ms'])}, "
        f"max {ms(d['latency_max_ms'])} (telemetry read to setpoint sent)",
        f"telemetry   {d['telemetry_received']} received, "
        f"{sum(rejected.values())} refused {rejected or ''}; {d['missed_cycles']} missed cycles",
        f"setpoints   {d['setpoints_sent']} sent; failsafes {d['failsafes']}; "
        f"HOLD {'confirmed' if d['hold_confirmed'] else 'not confirmed'}",
        f"controller  {d['controller']}",
        f"gains       {d['gains_source']}",
    ]
    if d.get("ekf_origin"):
        o = d["ekf_origin"]
        lines.append(f"origin      {o['lat']:.7f}, {o['lon']:.7f} ({o['source']}): the mission "
                     "placed around it")
    for key in ("plot", "tlog", "csv"):
        if key in d:
            lines.append(f"{key:<11} {d[key]}")
    print("\n".join(lines), flush=True)
