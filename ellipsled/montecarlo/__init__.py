"""Monte Carlo campaigns (docs/scenarios.md), executed on Dask distributed.

- ``campaign``: the campaign data file (data/campaigns/*.toml), the per-run draw from
  (master seed, run_id), the dispersed Scenario;
- ``engine``: ``run_campaign`` (embedded LocalCluster or an existing scheduler), one task
  per run, rows appended as runs finish, resume, failures recorded;
- ``store``: the Parquet dataset folder DIR/results.parquet;
- ``summary``: DIR/summary.md and PNG plots;
- ``cli``: ``add_montecarlo_parser`` and ``scenario_for_run`` / ``apply_campaign_run``
  for ``ellipsled batch --from-campaign DIR --run ID``.
"""
from .campaign import Campaign, load_campaign, draw_run, apply_dispersion
from .cli import CampaignRun, add_montecarlo_parser, apply_campaign_run, scenario_for_run

__all__ = ["Campaign", "load_campaign", "draw_run", "apply_dispersion", "CampaignRun", "add_montecarlo_parser",
           "apply_campaign_run", "scenario_for_run"]
