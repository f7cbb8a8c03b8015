"""Shared by the UDP bridge tests: a bounded wait for loopback datagrams."""

from __future__ import annotations

import time


def poll_until(dev, predicate, tries: int = 300) -> bool:
    """Poll ``dev`` until ``predicate()`` holds, at most ``tries`` times 1 ms apart (loopback
    datagrams are normally there at once)."""
    for _ in range(tries):
        dev.poll()
        if predicate():
            return True
        time.sleep(0.001)
    return False
