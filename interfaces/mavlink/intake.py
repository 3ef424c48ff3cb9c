"""The vehicle's bounded intake of ground datagrams: what the radio can cost the flight
software is capped per call, whatever arrives.

``DatagramIntake.poll(handle)`` reads the UDP socket without blocking until it is empty or
the call's budget is spent — at most ``max_datagrams`` datagrams and ``budget_us`` of
time — and refuses, before any CRC or signature work, what cannot be a message for the
vehicle:

| refused                                   | counted as (signing.Reject) |
|-------------------------------------------|-----------------------------|
| longer than ``max_datagram_bytes``        | MALFORMED ("oversized")     |
| a MAVLink 1 frame                         | GARBAGE ("MAVLink 1")       |
| not a MAVLink 2 frame                     | GARBAGE                     |
| a frame cut short                         | TRUNCATED                   |
| the receiver's own system id (``own_sysid``) | OWN_SYSTEM               |
| a message id the vehicle does not take    | UNKNOWN_MESSAGE             |
| unsigned, and not allowed unsigned        | UNSIGNED                    |

Every frame of a datagram is judged on its own: a datagram is read as frames laid end
to end (what a ground station sends is one), each refused or passed by the rules above
and then given to ``SignedLink.receive_single`` (signature first: one HMAC, which also
authenticates the CRC bytes; then decoding). Bytes that are not a frame where one should
start end the datagram (the rest is refused with them). The time budget is checked before
each frame: frames of a datagram left when it is spent are kept for the next call. A frame
that passes the early refusals (verified, decoded and handled: what costs) is begun only
when the call's time left covers what such a frame costs: a high percentile
(``FRAME_COST_QUANTILE``) of the last ``FRAME_COST_RING`` such frames, at most a quarter
of the call's budget, so the last frame does not carry the call past its budget, while a
few slow frames (a command that reconfigures) do not move the estimate. A call with any
budget always takes up its first datagram (or what the last call left: a frame kept for
the next call is the first it takes up) and begins its first frame to verify, whatever is
left of its budget by then: the budget bounds what follows that frame, it never keeps a
command waiting call after call.

Refusals are also counted per sender address (``refused_by_sender``: the last
``max_senders`` senders refused; the others' refusals together in ``refused_other_senders``).

What the budget leaves waits in the socket for the next call; the socket's receive buffer
is sized to about one call's budget (``rcvbuf_bytes``), so the backlog, and the age of a
command in it, stay bounded: the kernel drops the excess, and the intake reads those
drops from the kernel's own counter of the socket (SO_MEMINFO, Linux). Nothing here
blocks or raises on network input.
"""
from __future__ import annotations

import select
import socket
import struct
import time
from collections import OrderedDict, deque
from collections.abc import Callable, Collection

from . import framing
from .signing.link import SignedLink
from .signing.verify import Reject, Rejection

SO_MEMINFO = getattr(socket, "SO_MEMINFO", 55)       # Linux: the socket's memory counters
SK_MEMINFO_DROPS = 8                                  # ... of which: datagrams dropped


def kernel_drops(sock: socket.socket) -> int | None:
    """Datagrams the kernel dropped at ``sock`` since it was opened (its receive buffer was
    full), from the socket's own counter (SO_MEMINFO); None where there is none (not Linux)."""
    try:
        return _MEMINFO.unpack(sock.getsockopt(socket.SOL_SOCKET, SO_MEMINFO, _MEMINFO.size))[SK_MEMINFO_DROPS]
    except (OSError, struct.error):
        return None
_MEMINFO = struct.Struct("=9I")

DEFAULT_MAX_DATAGRAMS = 256
DEFAULT_BUDGET_US = 2000.0
DEFAULT_MAX_DATAGRAM_BYTES = 4 * framing.MAX_FRAME_LEN        # a few frames; a ground station sends one
RCVBUF_PER_DATAGRAM = 1024      # the kernel doubles it: ~2 kB of accounting per small datagram
DEFAULT_MAX_SENDERS = 64
FRAME_COST_RING = 32            # verified frames whose cost the estimate is taken from ...
FRAME_COST_QUANTILE = 0.9       # ... its quantile: 3 slow frames in the ring move nothing


class DatagramIntake:
    def __init__(self, sock: socket.socket, link: SignedLink, *, accept: Collection[int],
                 max_datagrams: int = DEFAULT_MAX_DATAGRAMS,
                 budget_us: float = DEFAULT_BUDGET_US, max_datagram_bytes: int = DEFAULT_MAX_DATAGRAM_BYTES,
                 rcvbuf_bytes: int | None = None, clock_ns: Callable[[], int] = time.perf_counter_ns,
                 own_sysid: int | None = None, max_senders: int = DEFAULT_MAX_SENDERS):
        if max_datagrams < 1 or not budget_us > 0 or max_datagram_bytes < framing.MAX_FRAME_LEN:
            raise ValueError("intake: max_datagrams >= 1, budget_us > 0, max_datagram_bytes >= one frame")
        self.sock = sock
        self.link = link
        self.accept = frozenset(int(m) for m in accept)
        self.allow_unsigned = link.verifier.allow_unsigned
        self.max_datagrams = int(max_datagrams)
        self.budget_ns = int(budget_us * 1e3)
        self.max_datagram_bytes = int(max_datagram_bytes)
        self.clock_ns = clock_ns
        self._buf = bytearray(self.max_datagram_bytes)
        self._view = memoryview(self._buf)
        want = int(rcvbuf_bytes) if rcvbuf_bytes is not None else self.max_datagrams * RCVBUF_PER_DATAGRAM
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, want)
        self.rcvbuf_bytes = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        self.own_sysid = own_sysid
        self.max_senders = int(max_senders)
        self.refused_by_sender: OrderedDict[tuple[str, int], int] = OrderedDict()
        self.refused_other_senders = 0
        self._rest: tuple[bytes, tuple[str, int]] | None = None      # frames a spent budget left
        self.stats = {"datagrams": 0, "bytes": 0, "refused_early": 0, "kernel_drops": 0,
                      "budget_hits": 0, "rx_errors": 0, "frames": 0, "frames_deferred": 0}
        self._drops0 = self._kernel_drops_total()
        self.kernel_counts = self._drops0 is not None
        self.last_poll_ns = 0
        self.frame_ns: deque[int] = deque(maxlen=FRAME_COST_RING)   # verify + handle cost of the last frames
        self._poller = select.poll()
        self._poller.register(sock, select.POLLIN)

    def waiting(self) -> bool:
        """Anything to take up: frames a spent budget left, or a datagram (or a socket error)
        at the socket -- one poll(2) with no timeout, no exception: what an idle call costs."""
        return self._rest is not None or bool(self._poller.poll(0))

    def frame_estimate_ns(self, budget_ns: int) -> int:
        """What a verified frame is taken to cost in a call of ``budget_ns``: the
        FRAME_COST_QUANTILE of the last frames' costs, at most a quarter of the budget."""
        if not self.frame_ns:
            return 0
        costs = sorted(self.frame_ns)
        return min(costs[int(FRAME_COST_QUANTILE * (len(costs) - 1))], budget_ns // 4)

    def _kernel_drops_total(self) -> int | None:
        return kernel_drops(self.sock)

    def _report(self, refused: dict) -> None:
        """The call's early refusals, one report per reason (what the first one was like):
        a flood costs one event a reason per call, not one per datagram."""
        for reason, (count, sysid, compid, msgid, detail) in refused.items():
            self.stats["refused_early"] += count
            self.link.verifier.reject(Rejection(reason, sysid, compid, msgid, -1, detail, count))

    def count_sender(self, addr, n: int = 1) -> None:
        """``n`` more refusals from ``addr`` (kept for the last ``max_senders`` senders)."""
        by = self.refused_by_sender
        if addr in by:
            by[addr] += n
            by.move_to_end(addr)
            return
        if len(by) >= self.max_senders:
            self.refused_other_senders += by.popitem(last=False)[1]
        by[addr] = n

    def _frames(self, view, size: int, addr, handle, refuse, over_budget, fits) -> int | None:
        """Judge and pass on the frames of one datagram (``view[:size]``), laid end to end.
        Returns None when done, or the offset of the first frame left for the next call
        because ``over_budget()`` said so, or ``fits()`` that a frame to verify does not."""
        i = 0
        st = self.stats
        link, verifier = self.link, self.link.verifier
        clock = self.clock_ns
        while i < size:
            if i and over_budget():
                return i
            b0 = view[i]
            if b0 == framing.MAGIC_V1:
                refuse(addr, Reject.GARBAGE, detail="MAVLink 1")
                return None
            if size - i < framing.HEADER_LEN_V2 + framing.CRC_LEN or b0 != framing.MAGIC_V2:
                refuse(addr, Reject.GARBAGE, detail=f"{size - i} bytes, not MAVLink 2")
                return None
            plen, iflags = view[i + 1], view[i + 2]
            frame_len = framing.HEADER_LEN_V2 + plen + framing.CRC_LEN \
                + (framing.SIGNATURE_LEN if iflags & framing.IFLAG_SIGNED else 0)
            sysid, compid = view[i + 5], view[i + 6]
            msgid = view[i + 7] | view[i + 8] << 8 | view[i + 9] << 16
            if frame_len > size - i:
                refuse(addr, Reject.TRUNCATED, sysid, compid, msgid, f"{size - i} of {frame_len} bytes")
                return None
            j, i = i, i + frame_len
            if sysid == self.own_sysid:
                reason, detail = Reject.OWN_SYSTEM, "the receiver's own system id"
            elif msgid not in self.accept:
                reason, detail = Reject.UNKNOWN_MESSAGE, "not taken by the vehicle"
            elif not iflags & framing.IFLAG_SIGNED and msgid not in self.allow_unsigned:
                reason, detail = Reject.UNSIGNED, ""
            else:
                reason = None
            if reason is not None:
                st["frames"] += 1
                refuse(addr, reason, sysid, compid, msgid, detail)
                continue
            if not fits():
                return j
            st["frames"] += 1
            t = clock()
            before = verifier.rejected
            msgs = link.receive_single(view[j:i])
            if verifier.rejected != before:
                self.count_sender(addr, verifier.rejected - before)
            for msg in msgs:
                handle(msg, addr)
            self.frame_ns.append(clock() - t)
        return None

    def poll(self, handle: Callable[[object, tuple[str, int]], None], budget_ns: int | None = None,
             least: bool = True) -> int:
        """Read and pass on what the budget allows; ``handle(msg, addr)`` gets every
        verified, decoded message. ``budget_ns``: this call's time, if less than the
        configured budget (the caller's slack). ``least``: the call's first datagram and
        frame are taken up whatever the budget leaves (False: a call that only reads on
        after another, within its budget alone). Returns the number of datagrams read."""
        t0 = self.clock_ns()
        budget = self.budget_ns if budget_ns is None else min(self.budget_ns, int(budget_ns))
        n = 0
        st = self.stats
        buf, view = self._buf, self._view
        refused: dict = {}            # reason -> [count, first sysid, compid, msgid, detail]

        def refuse(addr, reason, sysid=-1, compid=-1, msgid=-1, detail=""):
            self.count_sender(addr)
            r = refused.get(reason)
            if r is None:
                refused[reason] = [1, sysid, compid, msgid, detail]
            else:
                r[0] += 1

        def over_budget() -> bool:
            return self.clock_ns() - t0 >= budget

        estimate = self.frame_estimate_ns(budget)
        # a call with any budget takes up its first datagram (or the frames the last call
        # left) and begins its first frame to verify, however little time is left by then:
        # a budget smaller than a socket read and a frame must not keep a command waiting
        # call after call
        first = least and budget > 0
        begun = not least

        def fits() -> bool:
            """A frame to verify is begun: the call's first always, a later one when its
            estimated cost is left in the budget."""
            nonlocal begun
            if not begun:
                begun = True
                return True
            return self.clock_ns() - t0 + estimate <= budget

        if self._rest is not None and budget > 0:
            first = False
            rest, addr = self._rest
            self._rest = None
            at = self._frames(memoryview(rest), len(rest), addr, handle, refuse, over_budget, fits)
            if at is not None:
                self._rest = (rest[at:], addr)
                st["frames_deferred"] += 1
        while True:
            if self._rest is not None or n >= self.max_datagrams or (not first and over_budget()):
                st["budget_hits"] += 1
                break
            first = False
            try:
                # MSG_TRUNC: the datagram's real length, however much of it fits the buffer
                size, addr = self.sock.recvfrom_into(buf, 0, socket.MSG_TRUNC)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:                  # e.g. an ICMP error reported on a later recv
                st["rx_errors"] += 1
                n += 1
                continue
            n += 1
            st["datagrams"] += 1
            st["bytes"] += size
            if size > self.max_datagram_bytes:
                refuse(addr, Reject.MALFORMED, detail=f"oversized datagram, {size} bytes")
                continue
            at = self._frames(view, size, addr, handle, refuse, over_budget, fits)
            if at is not None:
                self._rest = (bytes(view[at:size]), addr)
                st["frames_deferred"] += 1
        if refused:
            self._report(refused)
        if self.kernel_counts:
            total = self._kernel_drops_total()
            if total is not None:
                st["kernel_drops"] = (total - self._drops0) & 0xFFFFFFFF
        self.last_poll_ns = self.clock_ns() - t0
        return n
