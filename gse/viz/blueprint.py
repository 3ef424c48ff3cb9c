"""The default Rerun blueprint shipped with every recording (docs/interfaces/index.md, Rerun).

Tabs, one per group of the spec's list, each a grid of views over the entities that
gse/viz/logger.py writes (the entity names are the contract between the two files).
"""
from __future__ import annotations

import rerun.blueprint as rrb

# Names of the views (tests read them back from the recording's blueprint store).
VIEW_NAMES = (
    "Bank vs reference", "Bank error", "Alpha and beta", "Body rates",
    "Torque x", "Torque y", "Torque z", "Jets firing", "Jet health", "Jet health now",
    "Jets on", "Adaptive parameters", "Altitude", "Speed", "Flight-path angle", "Mach",
    "Dynamic pressure", "Deceleration", "Trajectory", "Attitude", "Loop timing", "Slips",
    "Mode", "Ground track", "Predicted miss", "Events", "Event table", "Event catalogue",
)


def _ts(name: str, *contents: str) -> rrb.TimeSeriesView:
    return rrb.TimeSeriesView(name=name, origin="/", contents=list(contents))


def default_blueprint() -> rrb.Blueprint:
    trail = rrb.VisibleTimeRange("step", start=rrb.TimeRangeBoundary.infinite(),
                                 end=rrb.TimeRangeBoundary.cursor_relative())
    trail_t = rrb.VisibleTimeRange("sim_time", start=rrb.TimeRangeBoundary.infinite(),
                                   end=rrb.TimeRangeBoundary.cursor_relative())
    attitude = rrb.Grid(
        _ts("Bank vs reference", "/bank/actual_deg", "/bank/reference_deg"),
        _ts("Bank error", "/bank/error_deg"),
        _ts("Alpha and beta", "/aero/alpha_deg", "/aero/beta_deg"),
        _ts("Body rates", "/rates/**"),
        name="Attitude",
    )
    torque = rrb.Vertical(
        _ts("Torque x", "/torque/x/**"), _ts("Torque y", "/torque/y/**"), _ts("Torque z", "/torque/z/**"),
        name="Torque",
    )
    jets = rrb.Grid(
        _ts("Jets firing", "/jets/lanes"),
        rrb.StateTimelineView(name="Jet health", origin="/", contents=["/jets/health", "/fsw/mode"]),
        rrb.BarChartView(name="Jet health now", origin="/", contents=["/jets/health_code"]),
        _ts("Jets on", "/jets/n_firing", "/fsw/alloc_degraded"),
        name="Jets",
    )
    adapt = rrb.Horizontal(_ts("Adaptive parameters", "/adapt/**"), name="Adaptation")
    entry = rrb.Grid(
        _ts("Altitude", "/entry/altitude_km"), _ts("Speed", "/entry/speed_mps"),
        _ts("Flight-path angle", "/entry/gamma_deg"), _ts("Mach", "/entry/mach"),
        _ts("Dynamic pressure", "/entry/qbar_pa"), _ts("Deceleration", "/entry/decel_g"),
        name="Entry",
    )
    views3d = rrb.Horizontal(
        rrb.Spatial3DView(name="Trajectory", origin="/world", time_ranges=[trail, trail_t]),
        rrb.Spatial3DView(name="Attitude", origin="/attitude"),
        name="3D",
    )
    timing = rrb.Vertical(
        _ts("Loop timing", "/timing/compute_us", "/timing/alloc_us", "/timing/jitter_us"),
        _ts("Slips", "/timing/slips"),
        rrb.StateTimelineView(name="Mode", origin="/", contents=["/fsw/mode"]),
        name="Timing",
    )
    # the map: x east (longitude), y north (latitude) [deg], z up (logger: ViewCoordinates); every
    # predicted deploy point so far stays drawn (the trail), so the re-predictions converge
    # on the target before the viewer's eyes
    ground = rrb.Horizontal(
        rrb.Spatial3DView(name="Ground track", origin="/map", time_ranges=[trail, trail_t]),
        _ts("Predicted miss", "/guidance/predicted_miss_km"),
        column_shares=[3, 2], name="Map",
    )
    # the events logger.py writes: a table of them (their catalogue fields) and the catalogue
    events = rrb.Horizontal(rrb.DataframeView(name="Event table", origin="/events"),
                            rrb.TextDocumentView(name="Event catalogue", origin="/event_catalogue"),
                            column_shares=[3, 2], name="Events")
    tabs = rrb.Tabs(attitude, torque, jets, adapt, entry, views3d, ground, timing, events)
    return rrb.Blueprint(
        rrb.Vertical(tabs, rrb.TextLogView(name="Events", origin="/events"), row_shares=[4, 1]),
        rrb.TimePanel(state="expanded"),
        collapse_panels=False,
    )
