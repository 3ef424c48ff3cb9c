"""The flight software's output record (interfaces/records.py FSW_STATE), filled once per
control cycle: what the run history, the SIL's publication, the Rerun bridge and the MAVLink
telemetry read, so none of them assembles the FSW's outputs by hand.

Filling allocates no array: every field is written through a view made once.
"""
from __future__ import annotations

import math

import numpy as np

from interfaces.records import FSW_STATE, GUID_NPC, GUID_PREDICTION, GUID_TARGET, new


class OutputFiller:
    """Fills ``rec`` (an FSW_STATE record) from a FlightSoftware after its control cycle; the
    fields of FSW_STATE_SHELL are left to the rate-group driver (fsw/topology.py)."""

    def __init__(self, scenario):
        self.rec = new(FSW_STATE)
        self.v = {n: self.rec[n] for n in FSW_STATE.names}      # field views, made once
        # the deploy target is the scenario's, fixed for the flight: 0 and its flag clear when
        # there is none (never NaN on the wire)
        tlat, tlon = scenario.target_lat_rad, scenario.target_lon_rad
        has_target = tlat is not None and math.isfinite(tlat) and math.isfinite(tlon)
        self._target_flag = GUID_TARGET if has_target else 0
        self.v["target_lat_rad"][()] = tlat if has_target else 0.0
        self.v["target_lon_rad"][()] = tlon if has_target else 0.0

    def fill(self, fsw, u: np.ndarray) -> None:
        """The outputs of the cycle ``fsw`` has just run, whose jet command is ``u``."""
        v = self.v
        g = fsw.guidance
        v["k"][()] = fsw.k
        v["t_ns"][()] = int(round(fsw.t_s * 1e9))
        v["bank_ref_rad"][()] = g.phi_r
        v["bankdot_ref_radps"][()] = g.phidot_r
        v["bank_err_rad"][()] = fsw.bank_err_rad
        v["sigma_RN"][:] = g.sigma_RN
        v["u_cal_B"][:] = fsw.u_cal_B
        v["tau_alloc_B"][:] = fsw.tau_alloc_B
        v["theta_hat"][:] = fsw.control.theta_hat
        health = fsw.health
        v["eta_hat"][:] = health.eta
        v["health"][:] = health.state
        v["alloc_us"][()] = fsw.alloc_ns * 1e-3
        v["jets_cmd"][:] = u
        v["mode"][()] = int(fsw.modes.mode)
        v["alloc_degraded"][()] = fsw.allocator.degraded
        v["alloc_short"][()] = fsw.alloc_short
        v["deploy"][()] = fsw.deploy.code if fsw.deploy is not None else 0
        self._fill_guidance(fsw.entry)

    def _fill_guidance(self, e) -> None:
        """Entry guidance (mode npc): a value not available (no answer yet, profile mode,
        non-finite) is 0 with its guid_flags bit clear."""
        v = self.v
        flags = self._target_flag
        if e is None:
            v["guid_cycles"][()] = 0
            v["bank_cmd_rad"][()] = 0.0
            v["pred_lat_rad"][()] = 0.0
            v["pred_lon_rad"][()] = 0.0
        else:
            flags |= GUID_NPC
            v["guid_cycles"][()] = e.cycles
            v["bank_cmd_rad"][()] = e.bank_cmd if math.isfinite(e.bank_cmd) else 0.0
            p = e.pred_impact
            if e.cycles > 0 and math.isfinite(p[0]) and math.isfinite(p[1]):
                flags |= GUID_PREDICTION
                v["pred_lat_rad"][()] = p[0]
                v["pred_lon_rad"][()] = p[1]
            else:
                v["pred_lat_rad"][()] = 0.0
                v["pred_lon_rad"][()] = 0.0
        v["guid_flags"][()] = flags


