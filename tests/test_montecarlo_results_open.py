"""A campaign's DIR/results.parquet opens in standard tools as it is, the way a user reads it:
``pyarrow.dataset.dataset(path)``, ``pyarrow.parquet.read_table(path)``, ``pandas.read_parquet(path)``.

A small guided campaign (three 4-second runs, one of them made to raise, one part file per
run) gives parts where a column is null in one and text in another (``error``), and parts
without the guided figures (the raised run): every part must carry the same declared
schema, or a reader takes the first part's and fails ("Unsupported cast from string to
null") or drops the other parts' columns.
"""
from __future__ import annotations

import pyarrow as pa
import pyarrow.dataset as ds
import pyarrow.parquet as pq
import pytest

from common.config import DATA_DIR
from common.model import load_scenario
from ellipsled.montecarlo.campaign import campaign_base, load_campaign
from ellipsled.montecarlo.engine import RECORD_SCHEMA, execute_run, make_task, run_campaign
from ellipsled.montecarlo.store import ResultStore, rows_to_table

pytestmark = pytest.mark.timeout(300)

BREAK = 1
RUNS = 3


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """The guided campaign with faults early enough for 4-second runs, run BREAK raising;
    one part file per finished run (flush_rows=1), one local worker."""
    text = (DATA_DIR / "campaigns" / "guided.toml").read_text()
    assert "t_s = [2.0, 300.0]" in text
    text = text.replace("t_s = [2.0, 300.0]", "t_s = [1.0, 3.0]") + f"\n[testing]\nbreak_runs = [{BREAK}]\n"
    d = tmp_path_factory.mktemp("mc")
    (d / "guided-short.toml").write_text(text)
    res = run_campaign(d / "guided-short.toml", d / "out", runs=RUNS, duration_s=4.0, workers=1, progress=False,
                       flush_rows=1, summary=False)
    assert (res.recorded, res.failed_new) == (RUNS, 1)
    return d / "out" / "results.parquet"


def test_every_part_file_carries_the_declared_schema(results):
    parts = sorted(results.glob("part-*.parquet"))
    assert len(parts) == RUNS
    for p in parts:
        assert pq.read_schema(p).equals(RECORD_SCHEMA), p.name


def test_pyarrow_reads_the_folder_as_one_table(results):
    t = ds.dataset(results).to_table()
    assert t.schema.equals(RECORD_SCHEMA)
    rows = sorted(t.to_pylist(), key=lambda r: r["run_id"])
    assert [r["run_id"] for r in rows] == list(range(RUNS))
    # the column that is null in some parts and text in others
    assert [r["error"] is None for r in rows] == [i != BREAK for i in range(RUNS)]
    assert "fdir.delay_s" in rows[BREAK]["error"] and rows[BREAK]["status"] == "failed"
    ok = [r for r in rows if r["run_id"] != BREAK]
    assert all(isinstance(r["deploy_miss_km"], float) and r["guidance_mode"] == "npc" for r in ok)
    assert rows[BREAK]["deploy_miss_km"] is None
    assert pq.read_table(results).num_rows == RUNS                  # the issue's own reader


def test_pandas_reads_the_folder_as_one_frame(results):
    import pandas as pd
    df = pd.read_parquet(results).sort_values("run_id").reset_index(drop=True)
    assert list(df["run_id"]) == list(range(RUNS))
    assert list(df.columns) == RECORD_SCHEMA.names
    assert list(df["error"].isna()) == [i != BREAK for i in range(RUNS)]
    assert df["deploy_miss_km"].dtype == "float64" and df["run_id"].dtype == "int64"


def test_the_schema_declares_every_column_an_unguided_run_writes(tmp_path):
    """The default campaign's rows (the guided ones are the campaign above) fit the schema."""
    camp = load_campaign("default")
    base = campaign_base(camp.record(), load_scenario(camp.scenario))
    row = execute_run(make_task(camp, base, 0, camp.master_seed, 1.0))
    assert row["status"] == "ok", row.get("error")
    t = rows_to_table([row], RECORD_SCHEMA)
    assert t.schema.equals(RECORD_SCHEMA) and t.column("disp.density_waves").to_pylist() == [None]


def test_a_row_outside_the_schema_is_refused_before_it_is_written(tmp_path):
    st = ResultStore(tmp_path / "results.parquet", RECORD_SCHEMA)
    with pytest.raises(ValueError, match="run 7: columns not declared.*new_figure"):
        st.check({"run_id": 7, "new_figure": 1.0})
    with pytest.raises(ValueError, match="column t_end_s"):
        st.append([{"run_id": 7, "t_end_s": "late"}])
    assert st.parts() == []
    st.append([{"run_id": 7, "t_end_s": 3}])                       # an integer where a float is declared
    assert pq.read_table(st.parts()[0]).column("t_end_s").type == pa.float64()


def test_a_folder_of_the_earlier_format_is_not_resumed(tmp_path):
    """Its parts have another schema: new parts beside them would not make one table."""
    import json
    from ellipsled.montecarlo.engine import FORMAT, META_FILE, prepare_out
    camp = load_campaign("default")
    out = tmp_path / "mc"
    prepare_out(out, camp, 1, 10.0)
    meta = json.loads((out / META_FILE).read_text())
    assert meta["format"] == FORMAT
    (out / META_FILE).write_text(json.dumps(dict(meta, format=FORMAT - 1)))
    with pytest.raises(ValueError, match=f"format {FORMAT - 1}.*choose another --out"):
        prepare_out(out, camp, 1, 10.0)
