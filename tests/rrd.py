"""Reading Rerun recordings (.rrd) back: the ``rerun`` executable of this interpreter's
environment, each entity's record batches, and one component's values by step."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
from rerun.chunk import RrdReader

RERUN = str(Path(sys.executable).parent / "rerun")


def read_recording(path: Path) -> tuple[dict, RrdReader]:
    """(entity -> list of record-batch dicts (all its chunks), the reader)."""
    r = RrdReader(path)
    out: dict[str, list] = {}
    for c in r.stream():
        rb = c.to_record_batch()
        d = {name: (col.cast(pa.int64()) if pa.types.is_temporal(col.type) else col).to_pylist()
             for name, col in zip(rb.schema.names, rb.columns)}     # times as int64 [ns]
        out.setdefault(c.entity_path, []).append(d)
    return out, r


def column(chunks: list, comp: str) -> tuple[np.ndarray, np.ndarray, list]:
    """(steps, simulated times, values) of component ``comp`` over an entity's chunks, by step."""
    steps, times, vals = [], [], []
    for d in chunks:
        if "step" not in d:
            continue
        steps += d["step"]
        times += d["sim_time"]
        vals += d[comp]
    order = np.argsort(steps, kind="stable")
    return np.asarray(steps)[order], np.asarray(times, dtype=object)[order], [vals[i] for i in order]
