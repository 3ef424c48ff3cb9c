"""The campaign's results: a Parquet dataset folder ``DIR/results.parquet`` of part files.

Each append writes one new part file atomically (temporary name, fsync, rename), so a
reader (or a resumed campaign) sees whole parts only, whatever happened to the writer.
Any Parquet reader opens the folder as one table (``pyarrow.dataset.dataset(DIR /
"results.parquet")``); column types are unified across parts (a column that is all null in
one part takes its type from the others).
"""
from __future__ import annotations

import json
import os
import uuid
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

PART_GLOB = "part-*.parquet"


def flatten(summary: dict, prefix: str = "") -> dict:
    """summary.json as flat columns: nested tables as ``a.b``, lists (detections, pulses
    per jet, reversals...) as JSON text."""
    out = {}
    for k, v in summary.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten(v, f"{name}."))
        elif isinstance(v, (list, tuple)):
            out[name] = json.dumps(v)
        else:
            out[name] = v
    return out


def _column(values: list) -> pa.Array:
    kinds = {type(v) for v in values if v is not None}
    if kinds == {bool}:
        return pa.array(values, pa.bool_())
    if kinds and kinds <= {int}:
        return pa.array(values, pa.int64())
    if kinds and kinds <= {int, float}:
        return pa.array([None if v is None else float(v) for v in values], pa.float64())
    if kinds and kinds <= {str}:
        return pa.array(values, pa.string())
    if not kinds:
        return pa.nulls(len(values))
    return pa.array([None if v is None else json.dumps(v) if not isinstance(v, str) else v for v in values],
                    pa.string())


def rows_to_table(rows: list[dict]) -> pa.Table:
    names: dict[str, None] = {}
    for r in rows:
        names.update(dict.fromkeys(r))
    return pa.table({n: _column([r.get(n) for r in rows]) for n in names})


class ResultStore:
    """Append-only rows of one campaign, one part file per append."""

    def __init__(self, root: str | Path):
        self.root = Path(root)
        if self.root.exists() and not self.root.is_dir():
            raise ValueError(f"{self.root}: expected a Parquet dataset folder, found a file")
        self.root.mkdir(parents=True, exist_ok=True)
        for tmp in self.root.glob(".tmp-*"):   # a writer died mid-write: never a visible part
            tmp.unlink(missing_ok=True)

    def parts(self) -> list[Path]:
        return sorted(self.root.glob(PART_GLOB))

    def append(self, rows: list[dict]) -> Path | None:
        if not rows:
            return None
        table = rows_to_table(rows)
        name = f"part-{len(self.parts()):06d}-{uuid.uuid4().hex[:12]}.parquet"
        tmp = self.root / f".tmp-{name}"
        pq.write_table(table, tmp)
        with open(tmp, "rb") as f:
            os.fsync(f.fileno())
        os.replace(tmp, self.root / name)
        dfd = os.open(self.root, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
        return self.root / name

    def run_ids(self) -> list[int]:
        """Every recorded run_id, duplicates included (there should be none)."""
        out: list[int] = []
        for p in self.parts():
            out += pq.read_table(p, columns=["run_id"]).column("run_id").to_pylist()
        return out

    def read(self) -> pa.Table:
        tables = [pq.read_table(p) for p in self.parts()]
        if not tables:
            return pa.table({"run_id": pa.array([], pa.int64())})
        t = pa.concat_tables(tables, promote_options="permissive")
        return t.take(pc.sort_indices(t, [("run_id", "ascending")]))

    def rows(self) -> list[dict]:
        return self.read().to_pylist()

    def row(self, run_id: int) -> dict:
        """The record of one run (ValueError if absent)."""
        t = self.read()
        m = t.filter(pc.equal(t.column("run_id"), int(run_id)))
        if m.num_rows == 0:
            raise ValueError(f"{self.root}: no record of run {run_id}")
        return m.to_pylist()[0]
