"""The benchmarks: scripts that measure the companion (its speed, latency, resources, and how well
it tracks on the bundled plant, ArduPilot SITL and PX4 SITL) and print figures; they assert nothing.

Run each from the checkout, as ``python -m benchmarks.NAME [--help]`` or ``python
benchmarks/NAME.py``; docs/benchmarks.md gives the current figure of each with its command.
May import: ``companion``'s library layers (never ``companion.commands``: what a benchmark needs
of a command lives below it), ``sitl_plant`` and ``testbed`` (the SITL launchers, missions and
scoring they share with the tests); one benchmark imports another only as ``benchmarks.NAME``.
"""
