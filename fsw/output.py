"""The flight software's output record (interfaces/records.py FSW_STATE), filled once per
control cycle: what the run history, the SIL's publication, the Rerun bridge and the MAVLink
telemetry read, so none of them assembles the FSW's outputs by hand.

Filling allocates no array: one compiled call (``fill_record``) writes every field through a
one-element view of the record made once. The control cycle's usual path calls
``fill_record`` from inside its own compiled tail (fsw/flightsoftware.py ``finish_cycle``);
the rare paths (jets held off, no frame) through ``OutputFiller.fill``. Both take their
arguments from ``OutputFiller.fill_args``.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from interfaces.records import FSW_STATE, GUID_NPC, GUID_PREDICTION, GUID_TARGET, new

_NO_PREDICTION = np.zeros(2)     # profile mode: no guidance answer to report


@njit(cache=True)
def fill_record(r, target_flag, u, short, torques, alloc_ns, mode, degraded, deploy, npc, guid_cycles, bank_cmd,
                pred, k, t_s, phi_r, phidot_r, bank_err_rad, sigma_RN, theta_hat, eta, health):
    """Write one cycle's outputs into ``r[0]`` (FSW_STATE). ``torques``: the SAMI torque and the
    allocated one in its first six (fsw/flightsoftware.py FlightSoftware's torques' buffer).
    Entry guidance (``npc``): a value not available (no answer yet, non-finite) is 0 with its
    guid_flags bit clear; profile mode reports none of them."""
    q = r[0]
    q.k = k
    q.t_ns = np.int64(np.rint(t_s * 1e9))     # round half to even, as Python's round()
    q.bank_ref_rad = phi_r
    q.bankdot_ref_radps = phidot_r
    q.bank_err_rad = bank_err_rad
    for i in range(3):
        q.sigma_RN[i] = sigma_RN[i]
        q.u_cal_B[i] = torques[i]
        q.tau_alloc_B[i] = torques[3 + i]
    for i in range(theta_hat.shape[0]):
        q.theta_hat[i] = theta_hat[i]
    for i in range(eta.shape[0]):
        q.eta_hat[i] = eta[i]
        q.health[i] = health[i]
        q.jets_cmd[i] = u[i]
    q.alloc_us = alloc_ns * 1e-3
    q.mode = mode
    q.alloc_degraded = degraded
    q.alloc_short = short
    q.deploy = deploy
    flags = target_flag
    if npc:
        flags |= GUID_NPC
        q.guid_cycles = guid_cycles
        q.bank_cmd_rad = bank_cmd if math.isfinite(bank_cmd) else 0.0
        if guid_cycles > 0 and math.isfinite(pred[0]) and math.isfinite(pred[1]):
            flags |= GUID_PREDICTION
            q.pred_lat_rad = pred[0]
            q.pred_lon_rad = pred[1]
        else:
            q.pred_lat_rad = 0.0
            q.pred_lon_rad = 0.0
    else:
        q.guid_cycles = 0
        q.bank_cmd_rad = 0.0
        q.pred_lat_rad = 0.0
        q.pred_lon_rad = 0.0
    q.guid_flags = flags


class OutputFiller:
    """Fills ``rec`` (an FSW_STATE record) from a FlightSoftware after its control cycle; the
    fields of FSW_STATE_SHELL are left to the rate-group driver (fsw/topology.py)."""

    def __init__(self, scenario):
        self.rec = new(FSW_STATE)
        self.one = self.rec.reshape(1)       # the same record as a one-element array (compiled code)
        # the deploy target is the scenario's, fixed for the flight: 0 and its flag clear when
        # there is none (never NaN on the wire)
        tlat, tlon = scenario.target_lat_rad, scenario.target_lon_rad
        has_target = tlat is not None and math.isfinite(tlat) and math.isfinite(tlon)
        self.target_flag = GUID_TARGET if has_target else 0
        self.rec["target_lat_rad"] = tlat if has_target else 0.0
        self.rec["target_lon_rad"] = tlon if has_target else 0.0

    def fill_args(self, fsw) -> tuple:
        """``fill_record``'s arguments after the record, ``target_flag``, ``u``, ``short`` and the
        torques: the outputs of the cycle ``fsw`` has just run that are not the jet command's. (17
        items: CPython 3.11 keeps every freed 20-item tuple on a free list it never takes them back
        from, up to 2,000 -- a new memory block each cycle, a pool every few dozen.)"""
        g = fsw.guidance
        health = fsw.health
        e = fsw.entry
        npc = e is not None
        return (fsw.alloc_ns, int(fsw.modes.mode), fsw.allocator.degraded,
                fsw.deploy.code if fsw.deploy is not None else 0, npc,
                e.cycles if npc else 0, float(e.bank_cmd) if npc else 0.0, e.pred_impact if npc else _NO_PREDICTION,
                fsw.k, fsw.t_s, g.phi_r, g.phidot_r, fsw.bank_err_rad, g.sigma_RN, fsw.control.theta_hat, health.eta,
                health.state)

    def fill(self, fsw, u: np.ndarray) -> None:
        """The outputs of the cycle ``fsw`` has just run, whose jet command is ``u``."""
        fill_record(self.one, self.target_flag, u, fsw.alloc_short, fsw.torques, *self.fill_args(fsw))
