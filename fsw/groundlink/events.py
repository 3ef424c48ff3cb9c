"""The MAVLink events interface of the ground link (interfaces/mavlink/README.md, "Events"):
every FSW event the catalogue describes goes down as an EVENT message besides its
STATUSTEXT, with a sequence number a ground station checks for gaps; CURRENT_EVENT_SEQUENCE
says the last one once a second; REQUEST_EVENT (read-only: accepted unsigned, policy.py)
is answered with the EVENTs still held, or RESPONSE_EVENT_ERROR for those no longer held.
What the EVENT ids and arguments mean is the events metadata file the link serves through
component metadata (metadata.py; interfaces/event_metadata.py).

An event the EVENT message cannot carry goes as STATUSTEXT only and takes no sequence
number: a code the catalogue does not know, or an event emitted in the older text form
whose entry has arguments the EVENT would carry (the text gives no values).

``EventDownlink`` is the protocol's state; ``GroundLink`` is link.GroundLink with it
wired in: the events' share of a tick counts two frames for an event that goes as EVENT
too, REQUEST_EVENT is answered to the requester within its read budget (as every read),
and CURRENT_EVENT_SEQUENCE is also answered to MAV_CMD_REQUEST_MESSAGE.
"""
from __future__ import annotations

from collections import deque

from interfaces.event_catalogue import BY_NAME, EventDef, Form
from interfaces.mavlink import dialect as mav

from . import link

HELD = 128                        # EVENT messages kept for re-requests
MAX_ANSWERS = 16                  # sequences answered for one REQUEST_EVENT
SEQUENCE_PERIOD_S = 1.0           # CURRENT_EVENT_SEQUENCE period
_HALF = 0x8000                    # sequence numbers are uint16: newer = less than half a turn ahead


class EventDownlink:
    """Sequence numbers, the EVENTs held for re-requests, and the answers to them."""

    def __init__(self) -> None:
        self.next_seq = 0
        self._held: deque[tuple[int, object]] = deque(maxlen=HELD)
        self.stats = {"events": 0, "requests": 0, "resent": 0, "unavailable": 0}

    @staticmethod
    def carried(ev) -> tuple[EventDef, Form, dict] | None:
        """(entry, form, arguments) of a common.events.Event an EVENT can carry, else None."""
        entry = BY_NAME.get(ev.code)
        if entry is None:
            return None
        if ev.args is None:                  # emitted as text: only an entry with no values to carry
            return (entry, entry.forms[0], {}) if len(entry.forms) == 1 and not entry.wire_args(entry.forms[0]) \
                else None
        args = dict(ev.args)
        return entry, entry.form(args), args

    def message(self, ev, carried: tuple[EventDef, Form, dict], keep: bool = True):
        """The EVENT of ``ev`` with the next sequence number; ``keep`` False: a trial
        encoding (warm-up) that takes no number."""
        entry, form, args = carried
        level = int(ev.severity) & 0xF
        msg = mav.MAVLink_event_message(0, 0, entry.event_id(form.index),
                                        int(max(0.0, ev.t_s) * 1000.0) & 0xFFFFFFFF, self.next_seq,
                                        level << 4 | level, list(entry.pack(form, args)))
        if keep:
            self._held.append((self.next_seq, msg))
            self.next_seq = (self.next_seq + 1) & 0xFFFF
            self.stats["events"] += 1
        return msg

    def current_sequence(self):
        """CURRENT_EVENT_SEQUENCE: the sequence number of the last EVENT sent."""
        return mav.MAVLink_current_event_sequence_message((self.next_seq - 1) & 0xFFFF, 0)

    def answer(self, req) -> list:
        """REQUEST_EVENT ``req``: the EVENT of each requested sequence number still held,
        RESPONSE_EVENT_ERROR (with the oldest held) for one no longer held, at most
        MAX_ANSWERS; sequence numbers not sent yet end the answer."""
        self.stats["requests"] += 1
        held = dict(self._held)
        oldest = self._held[0][0] if self._held else self.next_seq
        out = []
        for i in range(min(MAX_ANSWERS, ((req.last_sequence - req.first_sequence) & 0xFFFF) + 1)):
            seq = (req.first_sequence + i) & 0xFFFF
            if not 0 < (self.next_seq - seq) & 0xFFFF <= _HALF:
                break
            if seq in held:
                out.append(held[seq])
                self.stats["resent"] += 1
            else:
                out.append(mav.MAVLink_response_event_error_message(
                    req.get_srcSystem(), req.get_srcComponent(), seq, oldest, mav.MAV_EVENT_ERROR_REASON_UNAVAILABLE))
                self.stats["unavailable"] += 1
        return out


class GroundLink(link.GroundLink):
    """link.GroundLink with the MAVLink events interface (the module docstring)."""

    def __init__(self, fsw, key, **kwargs) -> None:
        super().__init__(fsw, key, **kwargs)
        self.event_downlink = EventDownlink()
        self._sequence_due = 0.0
        self.services.oneshot[mav.MAVLINK_MSG_ID_CURRENT_EVENT_SEQUENCE] = \
            lambda p: [self.event_downlink.current_sequence()]

    def handle(self, msg, addr: tuple[str, int]) -> None:
        if msg.get_msgId() != mav.MAVLINK_MSG_ID_REQUEST_EVENT:
            super().handle(msg, addr)
            return
        if not self._for_me(msg):
            return
        signed = bool(msg.get_signed())
        if not signed:                       # read-only (policy.py): within the sender's read budget
            if not self._may_read(addr):
                return
            self.stats["unsigned_reads"] += 1
        replies = self.event_downlink.answer(msg)
        if not signed and len(replies) > 1:
            replies = replies[:1 + self._take_reads(addr, len(replies) - 1)]
        for reply in replies:
            self._reply(reply, addr)

    def _event_frames(self, ev) -> int:
        return 1 + (self.event_downlink.carried(ev) is not None)

    def _send_event(self, ev) -> None:
        """Event ``ev``'s EVENT (when it has one), then its STATUSTEXT (link.GroundLink)."""
        carried = self.event_downlink.carried(ev)
        if carried is not None:
            self._send(self.event_downlink.message(ev, carried, keep=not self._pack_only))
        super()._send_event(ev)

    def _send_events(self, budget: int, forced: int = 0) -> None:
        """The new events as link.GroundLink sends them (each event's EVENT then its
        STATUSTEXT), then CURRENT_EVENT_SEQUENCE when due."""
        super()._send_events(budget, forced)
        down, now = self.event_downlink, self.clock()
        if now >= self._sequence_due or self._pack_only:
            self._send(down.current_sequence())
            if self._pack_only:              # warm-up: encode the answer to a re-request once too
                self._send(mav.MAVLink_response_event_error_message(0, 0, 0, 0, 0))
            else:
                self._sequence_due = now + SEQUENCE_PERIOD_S
