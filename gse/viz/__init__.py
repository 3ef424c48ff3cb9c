"""Rerun dashboards (docs/interfaces/index.md, "Rerun"): one logger for batch and live runs.

- ``RerunLogger`` (logger.py): buffers truth / FSW rows and sends them with
  ``send_columns`` every N steps or T seconds, on the ``sim_time`` and ``step`` timelines;
- ``default_blueprint`` (blueprint.py): the layout shipped with every recording;
- ``open_sinks`` (sinks.py): 'viewer' | 'web' | 'file' | 'none' (and '+' combinations);
- ``record_history`` (record.py): the same recording from a finished batch run;
- ``bridge_main`` (bridge.py): the ``ellipsled viz`` process (Zenoh -> RerunLogger).
"""
from gse.viz import rerun_log  # noqa: F401  (first: Rerun's log filter, before any module loads rerun)
from gse.viz.blueprint import default_blueprint
from gse.viz.logger import RerunLogger, VehicleGlyph, glyph_from_vehicle
from gse.viz.record import record_history
from gse.viz.sinks import Sinks, open_sinks

__all__ = ["RerunLogger", "VehicleGlyph", "glyph_from_vehicle", "default_blueprint",
           "open_sinks", "Sinks", "record_history"]
