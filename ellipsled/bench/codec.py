"""Codec benchmark (interfaces/codec.py): encode and decode cost of the SENSORS and JETS
frames (header, CRC-32, finiteness and sequence checks) against the bare copy of the
record bytes (``bytes(rec)`` / ``np.frombuffer``) in the same run.

    python -m ellipsled.bench.codec [--quick]
"""
from __future__ import annotations

import gc
import sys
import time

import numpy as np

from interfaces import records
from interfaces.codec import Codec

from .rows import NO_TARGET, Row, fmt, row


def _stats(ns: np.ndarray) -> dict:
    us = ns * 1e-3
    return {"p50_us": float(np.percentile(us, 50)), "p99_us": float(np.percentile(us, 99)),
            "max_us": float(us.max())}


def _one(name: str, dtype, n: int) -> dict:
    enc = Codec.for_schema(name)
    dec = Codec.for_schema(name)
    rec = records.new(dtype)
    rng = np.random.default_rng(1)
    for f in dtype.names:                              # realistic, finite contents
        a = rec[f]
        if a.dtype.kind == "f":
            rec[f] = rng.standard_normal(a.shape)
    clock = time.perf_counter_ns
    t_enc, t_dec, t_raw_enc, t_raw_dec = (np.empty(n, np.int64) for _ in range(4))
    bad = 0
    for i in range(200):                               # warm-up
        dec.decode(enc.encode(rec, i, i))
    gc_was = gc.isenabled()
    gc.disable()
    try:
        for i in range(n):
            seq = 1000 + i
            t0 = clock()
            buf = enc.encode(rec, seq, seq)
            t1 = clock()
            out = dec.decode(buf)
            t2 = clock()
            raw = bytes(rec)
            t3 = clock()
            back = np.frombuffer(raw, dtype, 1).reshape(())
            t4 = clock()
            t_enc[i], t_dec[i], t_raw_enc[i], t_raw_dec[i] = t1 - t0, t2 - t1, t3 - t2, t4 - t3
            bad += out is None or back is None
    finally:
        if gc_was:
            gc.enable()
    e, d = _stats(t_enc), _stats(t_dec)
    re_, rd = _stats(t_raw_enc), _stats(t_raw_dec)
    return {"bytes": enc.size, "payload_bytes": enc.payload_len,
            "encode_p50_us": e["p50_us"], "encode_p99_us": e["p99_us"], "encode_max_us": e["max_us"],
            "decode_p50_us": d["p50_us"], "decode_p99_us": d["p99_us"], "decode_max_us": d["max_us"],
            "baseline_bytes_p50_us": re_["p50_us"], "baseline_frombuffer_p50_us": rd["p50_us"],
            "rejected": int(bad + dec.rejected())}


def run(quick: bool) -> dict:
    n = 5_000 if quick else 50_000
    s = _one("SENSORS", records.SENSORS, n)
    j = _one("JETS", records.JETS, n)
    return {"figure": "codec encode/decode per frame [us] vs a bare bytes copy", "frames": n,
            "sensors": s, "jets": j,
            "sensors_roundtrip_p99_us": s["encode_p99_us"] + s["decode_p99_us"],
            "jets_roundtrip_p99_us": j["encode_p99_us"] + j["decode_p99_us"],
            "rejected": s["rejected"] + j["rejected"]}


def rows(res: dict) -> list[Row]:
    cd = res.get("codec") or {}
    if not cd:
        return []
    R = []
    for name, key in (("SENSORS", "sensors"), ("JETS", "jets")):
        s = cd.get(key) or {}
        R.append(row(f"codec {name} encode / decode p50 [us]", f"{fmt(s.get('encode_p50_us'))} / {fmt(s.get('decode_p50_us'))}",
                     f"bytes() {fmt(s.get('baseline_bytes_p50_us'))} / frombuffer {fmt(s.get('baseline_frombuffer_p50_us'))}",
                     "", "", NO_TARGET))
    return R


if __name__ == "__main__":
    import json
    print(json.dumps(run("--quick" in sys.argv), indent=2))
