"""The campaign's results: a Parquet dataset folder ``DIR/results.parquet`` of part files.

Each append writes one new part file atomically (temporary name, fsync, rename), so a
reader (or a resumed campaign) sees whole parts only, whatever happened to the writer.
A campaign's store writes every part with the same explicit schema (the run record's,
engine.RECORD_SCHEMA: every column, its type fixed), so any Parquet reader opens the folder
as one table as it is: ``pyarrow.dataset.dataset(DIR / "results.parquet")``,
``pandas.read_parquet(...)``, DuckDB's ``read_parquet('.../*.parquet')``. Without a schema
(ad-hoc tables, tests) each column's type is inferred from its values.
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


def check_columns(rows: list[dict], schema: pa.Schema) -> None:
    """ValueError naming the columns of ``rows`` that ``schema`` does not declare."""
    extra = sorted({n for r in rows for n in r} - set(schema.names))
    if extra:
        ids = sorted({r.get("run_id") for r in rows if set(r) - set(schema.names)}, key=str)
        raise ValueError(f"run {', '.join(map(str, ids))}: columns not declared in the record's schema: "
                         f"{', '.join(extra)}")


def rows_to_table(rows: list[dict], schema: pa.Schema | None = None) -> pa.Table:
    """The rows as a table: with ``schema``, exactly its columns and types (absent values
    null; an undeclared column or a value of another type is a ValueError); without, the
    columns of the rows with types inferred from their values."""
    if schema is None:
        names: dict[str, None] = {}
        for r in rows:
            names.update(dict.fromkeys(r))
        return pa.table({n: _column([r.get(n) for r in rows]) for n in names})
    check_columns(rows, schema)
    cols = []
    for f in schema:
        try:
            cols.append(pa.array([r.get(f.name) for r in rows], f.type))
        except (pa.ArrowInvalid, pa.ArrowTypeError, TypeError, OverflowError) as e:
            raise ValueError(f"column {f.name}: not {f.type}: {e}") from None
    return pa.Table.from_arrays(cols, schema=schema)


class ResultStore:
    """Append-only rows of one campaign, one part file per append. ``schema``: the one every
    part is written with (None: inferred per part, for ad-hoc stores)."""

    def __init__(self, root: str | Path, schema: pa.Schema | None = None):
        self.root = Path(root)
        self.schema = schema
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
        table = rows_to_table(rows, self.schema)
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

    def check(self, row: dict) -> None:
        """ValueError if ``row`` would not fit this store's schema (before buffering it)."""
        if self.schema is not None:
            rows_to_table([row], self.schema)

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
