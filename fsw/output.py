"""The flight software's output record (interfaces/records.py FSW_STATE), filled once per
control cycle: what the run history, the SIL's publication, the Rerun bridge and the MAVLink
telemetry read, so none of them assembles the FSW's outputs by hand.

Filling allocates no array: the scalar fields are packed into the record in runs of adjacent
fields, one ``struct`` call per run (one call costs about what a single field view's
assignment does), the vectors copied through views made once.
"""
from __future__ import annotations

import math
import struct

import numpy as np

from interfaces.records import FSW_STATE, GUID_NPC, GUID_PREDICTION, GUID_TARGET, new

_KIND = {"q": "i", "b": "i", "d": "f", "B": "u", "?": "u"}


def _run(*fields: tuple[str, str]) -> tuple[int, struct.Struct]:
    """(offset, Struct) packing the adjacent FSW_STATE ``fields`` ((name, struct code), in
    record order, each code the field's own type) in one call."""
    off = FSW_STATE.fields[fields[0][0]][1]
    end = off
    for name, code in fields:
        dt, o = FSW_STATE.fields[name][:2]
        if o != end or dt.itemsize != struct.calcsize("<" + code) or dt.kind != _KIND[code]:
            raise AssertionError(f"FSW_STATE.{name}: not {code!r} at offset {end}")
        end += dt.itemsize
    return off, struct.Struct("<" + "".join(code for _, code in fields))


# the fields the cycle fills, by run (the loop timing of FSW_STATE_SHELL between them is not
# written here; the deploy target is the scenario's, packed again with its neighbours)
_HEAD = _run(("k", "q"), ("t_ns", "q"))
_REF = _run(("bank_ref_rad", "d"), ("bankdot_ref_radps", "d"), ("bank_err_rad", "d"))
_ALLOC = _run(("alloc_us", "d"))
_GUID = _run(("guid_cycles", "q"), ("target_lat_rad", "d"), ("target_lon_rad", "d"), ("pred_lat_rad", "d"),
             ("pred_lon_rad", "d"), ("bank_cmd_rad", "d"))
_FLAGS = _run(("mode", "b"), ("alloc_degraded", "?"), ("alloc_short", "?"), ("guid_flags", "B"), ("deploy", "B"))


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
        self._target = (float(tlat), float(tlon)) if has_target else (0.0, 0.0)
        self.v["target_lat_rad"][()], self.v["target_lon_rad"][()] = self._target

    def fill(self, fsw, u: np.ndarray) -> None:
        """The outputs of the cycle ``fsw`` has just run, whose jet command is ``u``."""
        v, rec = self.v, self.rec
        g = fsw.guidance
        off, st = _HEAD
        st.pack_into(rec, off, fsw.k, int(round(fsw.t_s * 1e9)))
        off, st = _REF
        st.pack_into(rec, off, g.phi_r, g.phidot_r, fsw.bank_err_rad)
        v["sigma_RN"][:] = g.sigma_RN
        v["u_cal_B"][:] = fsw.u_cal_B
        v["tau_alloc_B"][:] = fsw.tau_alloc_B
        v["theta_hat"][:] = fsw.control.theta_hat
        health = fsw.health
        v["eta_hat"][:] = health.eta
        v["health"][:] = health.state
        off, st = _ALLOC
        st.pack_into(rec, off, fsw.alloc_ns * 1e-3)
        v["jets_cmd"][:] = u
        flags = self._fill_guidance(fsw.entry)
        off, st = _FLAGS
        st.pack_into(rec, off, int(fsw.modes.mode), fsw.allocator.degraded, fsw.alloc_short, flags,
                     fsw.deploy.code if fsw.deploy is not None else 0)

    def _fill_guidance(self, e) -> int:
        """Entry guidance (mode npc): a value not available (no answer yet, profile mode,
        non-finite) is 0 with its guid_flags bit clear. Returns guid_flags."""
        flags = self._target_flag
        cycles, bank_cmd, plat, plon = 0, 0.0, 0.0, 0.0
        if e is not None:
            flags |= GUID_NPC
            cycles = e.cycles
            if math.isfinite(e.bank_cmd):
                bank_cmd = e.bank_cmd
            p = e.pred_impact
            if e.cycles > 0 and math.isfinite(p[0]) and math.isfinite(p[1]):
                flags |= GUID_PREDICTION
                plat, plon = p[0], p[1]
        off, st = _GUID
        st.pack_into(self.rec, off, cycles, self._target[0], self._target[1], plat, plon, bank_cmd)
        return flags
