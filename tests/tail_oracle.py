"""The control cycle's tail as Python code, the way main flew it before it became one compiled
call (fsw/flightsoftware.py ``finish_cycle``, fsw/output.py ``fill_record``): the truth the
kernels are held to bit for bit. ``PythonTailFlightSoftware`` is a FlightSoftware whose cycle
ends in this Python code (also the "before" of the timing script in docs/benchmarks.md)."""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from fsw.flightsoftware import FlightSoftware, bank_short, note_sent
from fsw.jetdriver import drive_jets
from fsw.output import _NO_PREDICTION, fill_record
from tests.front_oracle import PythonFrontFlightSoftware
from interfaces.event_catalogue import EV
from interfaces.records import FSW_STATE, GUID_NPC, GUID_PREDICTION, GUID_TARGET, new


class PythonSentRing:
    """The ring of answers by frame index, in Python (a list of indices)."""

    def __init__(self, ring: int, n: int):
        self.sent = np.zeros((ring, n), dtype=np.uint8)
        self.sent_k = [-2] * ring

    def note(self, k: int, u: np.ndarray) -> None:
        i = k % len(self.sent_k)
        k_slot = self.sent_k[i]
        if k_slot == k:
            if not np.array_equal(self.sent[i], u):
                self.sent_k[i] = -k - 3
        elif k_slot != -k - 3:
            self.sent[i] = u
            self.sent_k[i] = k


def python_bank_short(bank_axis, u_cal_B, tau_alloc_B, short_min_Nm: float, short_frac: float) -> bool:
    a0, a1, a2 = (float(a) for a in bank_axis)
    u0, u1, u2 = u_cal_B.tolist()
    t0, t1, t2 = tau_alloc_B.tolist()
    d = a0 * u0 + a1 * u1 + a2 * u2
    got = a0 * t0 + a1 * t1 + a2 * t2
    return abs(d) > short_min_Nm and (d - got) * (1.0 if d > 0.0 else -1.0) > short_frac * abs(d)


class PythonOutputFiller:
    """FSW_STATE filled field by field through views (main's OutputFiller)."""

    def __init__(self, scenario):
        self.rec = new(FSW_STATE)
        self.v = {n: self.rec[n] for n in FSW_STATE.names}
        tlat, tlon = scenario.target_lat_rad, scenario.target_lon_rad
        has_target = tlat is not None and math.isfinite(tlat) and math.isfinite(tlon)
        self._target_flag = GUID_TARGET if has_target else 0
        self.v["target_lat_rad"][()] = tlat if has_target else 0.0
        self.v["target_lon_rad"][()] = tlon if has_target else 0.0

    def fill(self, fsw, u: np.ndarray) -> None:
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
        e = fsw.entry
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


class PythonTailFlightSoftware(PythonFrontFlightSoftware):
    """FlightSoftware whose cycle ends in main's Python tail: the torque copy, the shortfall
    test, ``JetDriver.command``, the ring noted in Python, the Python output filler. Its head
    is main's Python head too (tests/front_oracle.py), which reads the Python ring."""

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        self._py_ring = PythonSentRing(self._ring, self.driver.n)
        self._output = PythonOutputFiller(self.scenario)
        self.output = self._output.rec
        # the front half reads the ring through _command_in_force: the Python ring's arrays
        self._sent = self._py_ring.sent

    def _command_in_force(self, u_k: int):
        if u_k == -1:
            return self._zero_u
        r = self._py_ring
        i = u_k % self._ring
        return r.sent[i] if r.sent_k[i] == u_k else None

    def _sent_for(self, u):
        self._py_ring.note(self.k, u)
        return u

    def _held_off(self, t_s):
        u = self._sent_for(self._hold_off(t_s))
        self._output.fill(self, u)
        return u

    def _finish(self, t_s: float, u_alloc: np.ndarray) -> np.ndarray:
        self.tau_alloc_B[:] = self.dutycycle.tau_B
        self._check_bank_shortfall(t_s, python_bank_short(self.bank_axis_B, self.u_cal_B, self.tau_alloc_B,
                                                    self._bank_short_min_Nm, self.params["control.shortfall_frac"]))
        self._tau_last = tuple(self.tau_alloc_B.tolist())
        self._have_prev = True
        u = self._sent_for(self.driver.command(u_alloc, self.modes.jets_enabled))
        self._output.fill(self, u)
        return u


@njit(cache=True)
def main_finish_cycle(tau_B, u_alloc, gate, inhibit, last, pulses, on_time_s, mdot_kgps, dt_s, sent, sent_k,
                      bank_axis_B, short_min_Nm, short_frac,
                      r, target_flag, alloc_ns, mode, degraded, deploy, npc, guid_cycles, bank_cmd, pred,
                      k, t_s, phi_r, phidot_r, bank_err_rad, sigma_RN, u_cal_B, tau_alloc_B, theta_hat, eta, health):
    """main's ``finish_cycle`` before its arrays were packed (35 arguments, 18 arrays). Today's
    ``fill_record`` takes the torques' buffer: it comes in ``u_cal_B``'s place (u_cal_B is its
    first three)."""
    for i in range(3):
        tau_alloc_B[i] = tau_B[i]
    short = bank_short(bank_axis_B, u_cal_B, tau_alloc_B, short_min_Nm, short_frac)
    used = drive_jets(u_alloc, gate, inhibit, last, pulses, on_time_s, mdot_kgps, dt_s)
    note_sent(sent, sent_k, k, last)
    fill_record(r, target_flag, last, short, u_cal_B, alloc_ns, mode, degraded, deploy, npc, guid_cycles, bank_cmd,
                pred, k, t_s, phi_r, phidot_r, bank_err_rad, sigma_RN, theta_hat, eta, health)
    return used, short


class UnpackedTailFlightSoftware(FlightSoftware):
    """FlightSoftware whose tail is main's before the packing: the 35-argument kernel, and no
    rehearsal of the tail (the "before" of the tail's timing, docs/changelog.md)."""

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        d = self.driver
        self._unpacked = (d.inhibit, d.last_command, d.pulses, d.on_time_s, d._mdot_kgps, d.dt_s, self._sent,
                          self._sent_k)

    def _finish(self, t_s: float, u_alloc: np.ndarray) -> np.ndarray:
        driver, out = self.driver, self._output
        used, short = main_finish_cycle(self.dutycycle.tau_B, u_alloc, driver.armed and self.modes.jets_enabled,
                                        *self._unpacked,
                                        self.bank_axis_B, self._bank_short_min_Nm,
                                        self.params["control.shortfall_frac"],
                                        out.one, out.target_flag, *self._main_fill_args())
        driver.count(used)
        self._check_bank_shortfall(t_s, short)
        self._tau_last = tuple(self.tau_alloc_B.tolist())
        self._have_prev = True
        return driver.last_command

    def _main_fill_args(self) -> tuple:
        """main's ``OutputFiller.fill_args`` (19 items: u_cal_B -- here the torques' buffer, whose first
        three it is -- and tau_alloc_B each its own)."""
        g = self.guidance
        health = self.health
        e = self.entry
        npc = e is not None
        return (self.alloc_ns, int(self.modes.mode), self.allocator.degraded,
                self.deploy.code if self.deploy is not None else 0, npc,
                e.cycles if npc else 0, float(e.bank_cmd) if npc else 0.0, e.pred_impact if npc else _NO_PREDICTION,
                self.k, self.t_s, g.phi_r, g.phidot_r, self.bank_err_rad, g.sigma_RN, self.torques,
                self.tau_alloc_B, self.control.theta_hat, health.eta, health.state)

    def _rehearse_tail(self) -> None:
        pass
