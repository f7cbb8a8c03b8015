"""Which pose packets move the tool: the session gate of the haptic pose stream (no I/O).

A *stream* is the packets of one session id from one address. The gate applies the packets of
one stream, the *session*, and nothing else:

* **Opening.** No stream is applied until one has sent :data:`OPEN_PACKETS` (3) consecutive
  counting packets, each ahead of the one before by 1 to :data:`SEQ_WINDOW` (mod 2^32). Streams
  are counted apart, so strays interleaved with the genuine stream neither open a session nor
  delay the genuine one; a single stray packet never moves the tool.
* **Within the session.** A packet of the session is applied when its sequence number is ahead
  of the last applied one by 1 to :data:`SEQ_WINDOW` (about 65 s of packets at 1 kHz). Anything
  else (older, repeated, far ahead) is stale. There is no time-out that forgets the last number,
  so a packet replayed after any idle time is refused.
* **The session stays with its sender.** Without a key, the session is bound to the address
  that opened it: the same session id from another address is a different stream. With a key,
  the tag authenticates the sender and the address may change (a NAT rebinding).
* **Taking over.** Another stream (a restarted device client: new session id) is adopted only
  when it has opened (3 counting packets) *and* the session has been silent for
  :data:`SESSION_TIMEOUT_S` (0.5 s). While the genuine device streams, nothing takes over.
  The session it replaces is retired: its id is never accepted again, so its packets cannot be
  replayed into a new session.

Without a key the gate contains strays and replays but cannot authenticate: a local process
that forges counting packets with a fresh id can still take over a session that has gone silent.
Bind loopback only, or use a key (see :mod:`~surgsim_envs.haptics.pose_protocol`).
"""

from __future__ import annotations

import math
from collections import OrderedDict, deque

#: packets ahead of the last applied one by 1..SEQ_WINDOW (mod 2^32) are applied
SEQ_WINDOW = 1 << 16
#: consecutive counting packets that open a stream
OPEN_PACKETS = 3
#: a stream may take over a session silent for longer than this (s)
SESSION_TIMEOUT_S = 0.5
#: candidate streams remembered at once (a poll reads at most a few dozen datagrams per servo
#: tick, so a genuine stream sending once per tick is never pushed out by a flood of others)
MAX_CANDIDATES = 1024
#: retired session ids remembered
MAX_RETIRED = 4096


def _ahead(seq: int, ref: int, window: int) -> bool:
    return 0 < ((seq - ref) & 0xFFFFFFFF) <= window


class SessionGate:
    """``admit(session, seq, addr, now)`` returns True when the pose must be applied (and records
    it). ``authenticated`` streams (packets whose tag verified) are not bound to an address."""

    def __init__(self, window: int = SEQ_WINDOW, open_packets: int = OPEN_PACKETS,
                 session_timeout: float = SESSION_TIMEOUT_S, authenticated: bool = False):
        self.window, self.open_packets = int(window), int(open_packets)
        self.session_timeout, self.authenticated = float(session_timeout), bool(authenticated)
        self.session: int | None = None
        self.addr = None
        self.last_seq: int | None = None
        self.last_time = -math.inf
        self.opened = 0       # sessions opened, the first included
        self.takeovers = 0    # sessions that replaced a silent one
        self._candidates: OrderedDict = OrderedDict()  # stream -> (last seq, count)
        self._retired: set[int] = set()
        self._retired_order: deque = deque()

    def _stream(self, session: int, addr):
        return session if self.authenticated else (session, addr)

    def _is_session(self, session: int, addr) -> bool:
        return session == self.session and (self.authenticated or addr == self.addr)

    def _count(self, key, seq: int) -> int:
        prev = self._candidates.pop(key, None)
        count = prev[1] + 1 if prev is not None and _ahead(seq, prev[0], self.window) else 1
        self._candidates[key] = (seq, count)
        while len(self._candidates) > MAX_CANDIDATES:
            self._candidates.popitem(last=False)
        return count

    def _retire(self, session: int) -> None:
        self._retired.add(session)
        self._retired_order.append(session)
        while len(self._retired_order) > MAX_RETIRED:
            self._retired.discard(self._retired_order.popleft())

    def admit(self, session: int, seq: int, addr, now: float) -> bool:
        if self.session is not None and self._is_session(session, addr):
            if not _ahead(seq, self.last_seq, self.window):
                return False
            self.last_seq, self.last_time = seq, now
            return True
        if session in self._retired:
            return False
        if session == self.session and not _ahead(seq, self.last_seq, self.window):
            return False  # the session's own packets, replayed from another address
        if self._count(self._stream(session, addr), seq) < self.open_packets:
            return False
        if self.session is not None:
            if now - self.last_time <= self.session_timeout:
                return False  # the session is alive: it keeps the stream
            if session != self.session:
                self._retire(self.session)
            self.takeovers += 1
        self._candidates.clear()
        self.session, self.addr, self.last_seq, self.last_time = session, addr, seq, now
        self.opened += 1
        return True
