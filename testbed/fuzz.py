"""Malformed MAVLink frames for the fuzz tests: random bytes, bit flips, truncations, wrong
lengths, wrong system ids, replays, and well-formed frames with NaN / infinite / huge fields.

Every frame is one datagram (bytes). :class:`Fuzzer` keeps the recent good frames of the stream
it corrupts (for bit flips, truncations and replays) and counts frames per category.
"""

from __future__ import annotations

import math
import random
from collections import Counter, deque
from collections.abc import Callable
from typing import Any

from testbed.safety import encoder, frame

CATEGORIES = ("random_bytes", "random_v2_header", "bit_flip", "truncated", "wrong_length",
              "wrong_ids", "replay", "bad_values")
WILD = (math.nan, -math.nan, math.inf, -math.inf, 1e7, -1e9, 3.4e38, -3.4e38, 1e30)


class Fuzzer:
    def __init__(self, seed: int, bad_values: Callable[[random.Random, Any], Any]):
        self.rng = random.Random(seed)
        self.recent: deque[bytes] = deque(maxlen=64)   # good frames seen lately
        self.counts: Counter[str] = Counter()
        self._bad_values = bad_values                   # (rng, encoder) -> message
        self._ours = encoder(None, sysid=1, compid=1)
        self._strangers = [encoder(None, sysid=s, compid=c)
                           for s, c in ((2, 1), (1, 2), (255, 190), (1, 0), (200, 1))]

    def good(self, data: bytes) -> bytes:
        self.recent.append(data)
        return data

    def frame(self) -> bytes:
        rng = self.rng
        kind = rng.choice(CATEGORIES)
        if kind in ("bit_flip", "truncated", "wrong_length", "replay") and len(self.recent) < 8:
            kind = "random_bytes"
        self.counts[kind] += 1
        if kind == "random_bytes":
            return rng.randbytes(rng.randint(1, 300))
        if kind == "random_v2_header":
            n = rng.randint(0, 255)
            return bytes([0xFD, n, rng.choice((0, 1, 2, 255)), 0, rng.randint(0, 255), 1, 1]) \
                + rng.randbytes(3) + rng.randbytes(rng.randint(0, n + 20))
        if kind in ("bit_flip", "truncated", "wrong_length", "replay"):
            old = self.recent[rng.randrange(len(self.recent) - 4)]   # not the newest few
        if kind == "bit_flip":
            data = bytearray(old)
            for _ in range(rng.randint(1, 4)):
                i = rng.randrange(len(data) * 8)
                data[i // 8] ^= 1 << (i % 8)
            return bytes(data)
        if kind == "truncated":
            return old[:rng.randrange(1, len(old))]
        if kind == "wrong_length":
            data = bytearray(old)
            data[1] = (data[1] + rng.choice((-3, -1, 1, 2, 40, 200))) % 256
            return bytes(data)
        if kind == "replay":
            return old                    # an earlier good frame, verbatim
        if kind == "wrong_ids":
            mav = rng.choice(self._strangers)
            return frame(mav, self._bad_values(rng, mav, plausible=True))
        return frame(self._ours, self._bad_values(rng, self._ours, plausible=False))


def wild(rng: random.Random) -> float:
    return rng.choice(WILD)
