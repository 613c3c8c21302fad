"""A link served by a thread, for a ``with`` block: the test bed's fakes, feeders and relays
(:class:`~testbed.fake_vehicle.FakeVehicle`, :class:`~testbed.mission_gcs.GroundStation`,
:class:`~testbed.gnss_input.GnssInjector` on a pymavlink link; :class:`~testbed.udp_proxy.Proxy`
and :class:`~testbed.field_faults.UdpStallProxy` on a UDP socket) share how they start, stop
and close."""

from __future__ import annotations

import threading
from typing import Any, Self


class LinkThread:
    """Subclasses open their link, call :meth:`_prepare_thread` in their constructor and loop
    in ``_run`` until ``self._stop`` is set; the thread starts on entry and, on exit, is stopped
    and joined, then the link closed (:meth:`_close`: ``self.conn``, a pymavlink link, unless
    a subclass closes another)."""

    conn: Any

    def _prepare_thread(self) -> None:
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self._close()

    def _close(self) -> None:
        self.conn.close()
