"""The parachute deploy trigger (docs/fsw/entry-guidance.md, deploy trigger): the flight
software decides when to deploy and commands it across the interface (JETS.deploy).

Two rules, chosen by ``deploy.trigger``:
- ``range`` (Mars 2020): deploy when the range to go is used up — the target abeam or behind,
  i.e. the along-track range to go <= 0, which is also where the distance to the target (the
  deploy miss) stops improving — provided the vehicle is inside the deploy box;
- ``velocity`` (MSL): deploy at ``deploy.mach`` inside the box.
Whichever rule, inside the box the trigger fires at the deploy-altitude floor
(``deploy.h_floor_m``) with range still to go: the range is traded for the altitude, the
corrector having failed to keep both (fsw/guidance/npc.py keeps the predicted deploy altitude
above that floor). And it fires before the vehicle leaves the box at its slow or low edge
(a margin above the box's Mach and altitude minima): a deploy at the box's edge by the
plant is a failure. The box is the vehicle file's [deploy] (common/model.py DeployBox), judged
on the FSW's own navigation (its Mach, its altitude, its dynamic pressure scaled by the
density estimate), never the plant's truth. The command, once given, is latched.
"""
from __future__ import annotations

import math

from common.events import EventLog
from interfaces.event_catalogue import EV
from interfaces.records import DEPLOY_EDGE, DEPLOY_FLOOR, DEPLOY_NONE, DEPLOY_RANGE, DEPLOY_VELOCITY

from ..params import Param
from .geometry import heading_error, planet_fixed, unit_from_latlon

PARAMS = [
    # design values of the mission, set before flight (a scenario's or campaign's [fsw.deploy]):
    # the trigger acts only in the deploy box, at the end of the entry
    Param("deploy.trigger", 0, 0, "", "deploy rule: range (range to go used up) or velocity (at deploy.mach)",
          choices=("range", "velocity"), ground_settable=False),
    Param("deploy.mach", 0.5, 5.0, "", "Mach of the velocity trigger", ground_settable=False),
    Param("deploy.h_floor_m", 0.0, 5e4, "m", "inside the box, deploy at this altitude even with range to go (0: off)",
          ground_settable=False),
    Param("deploy.mach_margin", 0.0, 1.0, "", "the trigger fires this far above the box's Mach minimum at the latest",
          ground_settable=False),
    Param("deploy.h_margin_m", 0.0, 1e4, "m", "... and this far above the box's altitude minimum",
          ground_settable=False),
]


class DeployTrigger:
    """``update(nav, t_s, k_rho)`` every control period; ``code`` is the DEPLOY_* code of the
    command (DEPLOY_NONE until it fires), ``command`` the JETS.deploy value (0 or 1)."""

    def __init__(self, scenario, params: dict, events: EventLog):
        box = scenario.vehicle.deploy_box
        if box is None:
            raise ValueError(f"vehicle {scenario.vehicle.name!r} has no [deploy] box")
        self.box = box
        self.params = params
        self.events = events
        self.omega_radps = scenario.planet.omega_radps
        self.radius_m = scenario.planet.radius_m
        tlat, tlon = scenario.target_lat_rad, scenario.target_lon_rad
        self.target_u = unit_from_latlon(tlat, tlon) if tlat is not None else None
        self.code = DEPLOY_NONE
        self.t_s = math.nan               # time of the command
        self.range_to_go_m = math.nan     # along-track range to go at the last update [+ ahead]
        self.in_box = False

    @property
    def command(self) -> int:
        return int(self.code != DEPLOY_NONE)

    def along_track_m(self, nav, t_s: float) -> float:
        """Range to go along the track: the distance to the target times the cosine of the
        heading error (<= 0 once the target is abeam or behind)."""
        x = planet_fixed(nav.r_N, nav.v_N, t_s, self.omega_radps)
        dpsi, ang = heading_error(x, self.target_u)
        return ang * self.radius_m * math.cos(dpsi)

    def update(self, nav, t_s: float, k_rho: float = 1.0) -> int:
        """Judge this control period; returns ``command``."""
        if self.code != DEPLOY_NONE:
            return 1
        p, box = self.params, self.box
        mach, h = nav.mach, nav.h_m
        qbar = nav.qbar_pa * k_rho
        self.in_box = box.inside(mach, qbar, h)
        rule = p["deploy.trigger"]
        if rule == "range" and self.target_u is not None:
            self.range_to_go_m = self.along_track_m(nav, t_s)
        code = DEPLOY_NONE
        if self.in_box:
            if rule == "velocity" or self.target_u is None:
                if mach <= p["deploy.mach"]:
                    code = DEPLOY_VELOCITY
            elif self.range_to_go_m <= 0.0:
                code = DEPLOY_RANGE
            if code == DEPLOY_NONE and h <= p["deploy.h_floor_m"]:
                code = DEPLOY_FLOOR
        if code == DEPLOY_NONE and (mach <= box.mach_min + p["deploy.mach_margin"]
                                    or h <= box.h_min_m + p["deploy.h_margin_m"]):
            code = DEPLOY_EDGE            # the last moment inside the box: the rule did not fire
        if code != DEPLOY_NONE:
            self.code, self.t_s = code, t_s
            rtg = self.range_to_go_m if math.isfinite(self.range_to_go_m) else 0.0
            self.events.emit(t_s, EV.DEPLOY_COMMAND, rule=code, mach=mach, h_km=h / 1e3, rtg_km=rtg / 1e3)
        return self.command
