"""The real-time FSW flies the newest sensor frame that decodes: garbage, a forged frame of a
second publisher or a truncated one arriving after a genuine frame is refused (counted by
the decoder) and the genuine frame is taken, not lost. Scripted samples, no transport."""
from __future__ import annotations

from types import SimpleNamespace

from ellipsled.sil.common import DecodeRehearsal
from ellipsled.sil.fsw_node import FswNode
from interfaces import records
from interfaces.codec import Codec, SequenceGuard


class Sub:
    """A polled subscriber holding scripted payloads."""

    def __init__(self, payloads):
        self.q = [SimpleNamespace(payload=SimpleNamespace(to_bytes=lambda b=b: b)) for b in payloads]

    def try_recv(self):
        return self.q.pop(0) if self.q else None


def _frame(enc: Codec, k: int, seq: int) -> bytes:
    rec = records.new(records.SENSORS)
    rec["k"] = k
    return enc.encode(rec, seq, 1_000 + seq)


def _node(payloads):
    dec = Codec.for_schema("SENSORS", guard=SequenceGuard(takeover_after_s=1.0))
    frame = records.new(records.SENSORS)
    node = SimpleNamespace(sub_sensors=Sub(payloads), frame=frame, dec=dec)
    node._accept = lambda s: dec.decode(s.payload.to_bytes(), out=frame) is not None
    return node


def test_garbage_after_a_genuine_frame_does_not_hide_it():
    plant, forger = Codec.for_schema("SENSORS"), Codec.for_schema("SENSORS")   # (one publisher id a process)
    genuine = [_frame(plant, k, k) for k in range(3)]
    node = _node([genuine[0]])
    assert FswNode._fetch_frame(node) == 0                 # the plant owns the key
    node.sub_sensors = Sub([genuine[1], b"\x00" * 37, genuine[2][:-5], _frame(forger, 99, 0), b"garbage"])
    assert FswNode._fetch_frame(node) == 1
    assert int(node.frame["k"]) == 1
    r = node.dec.rejects
    assert r["size"] == 3 and sum(r.values()) == 4, r           # each refusal counted (the forgery too)


def test_the_newest_genuine_frame_is_taken_and_nothing_is_left_queued():
    plant = Codec.for_schema("SENSORS")
    node = _node([_frame(plant, k, k) for k in range(4)] + [b"junk"])
    assert FswNode._fetch_frame(node) == 3
    assert node.sub_sensors.try_recv() is None
    assert FswNode._fetch_frame(node) is None          # nothing new: no frame


def test_only_garbage_gives_no_frame_and_keeps_the_last_one():
    node = _node([b"junk", b"\xff" * 400])
    node.frame["k"] = 7
    assert FswNode._fetch_frame(node) is None
    assert int(node.frame["k"]) == 7 and sum(node.dec.rejects.values()) == 2


def test_the_rehearsal_before_a_frame_touches_nothing_the_loop_flies_with():
    """The real-time FSW's rehearsal decodes the last frame again on scratch codecs: the
    frame it flies, its decoder's counts and its replay guard stay as they were (the same
    frame decoded again by the flying decoder would be refused as a replay)."""
    plant = Codec.for_schema("SENSORS")
    node = _node([_frame(plant, 0, 0)])
    assert FswNode._fetch_frame(node) == 0
    raw = _frame(plant, 1, 1)
    node.sub_sensors = Sub([raw])
    assert FswNode._fetch_frame(node) == 1
    node.frame["t_ns"] = 123
    snapshot = node.frame.copy()
    node.jets, node._warm_enc = records.new(records.JETS), Codec.for_schema("JETS")
    node._warm_frame = DecodeRehearsal("SENSORS", copy=True)
    node._warm_frame.last = raw                            # what FswNode._accept notes
    for _ in range(3):
        FswNode._rehearse(node)
    assert node.frame.tobytes() == snapshot.tobytes()
    warm = node._warm_frame
    assert int(warm._out["k"]) == 1 and warm._dec.decoded == 3 and sum(warm._dec.rejects.values()) == 0
    assert sum(node.dec.rejects.values()) == 0 and node.dec.decoded == 2
    node.sub_sensors = Sub([_frame(plant, 2, 2)])
    assert FswNode._fetch_frame(node) == 2                  # the flying decoder's guard moved on only by its own frames
