"""Error feedback across control cycles: the allocator's shortfall carried to the next demand.

One cycle's allocation picks one jet pattern, the exact optimum for that cycle's demand. Once
failures leave no pattern that gives bank torque without pitch/yaw spill, the same pattern wins
cycle after cycle (campaign 2026 run 190: +9 N m of roll where the duty-cycle LP,
fsw/controllability.py, holds +52 N m on average by spilling pitch/yaw one way in one cycle and
the other way in the next). The attitude loop integrates a bank shortfall but not the spill
that would cure it. A first-order sigma-delta does: each cycle asks for the demand plus the
shortfall left by the cycle before (demand asked - torque modelled), so the spill of one cycle is
asked back in the next and the average approaches what the duty cycles can hold.

The carry is clipped per axis to ``Allocator.carry_max`` (the box allowance, the same size in the
objective's weighted units on every axis; zero with the paper's sign box), so a demand beyond
reach neither winds it up nor shifts the objective's priorities between axes. It is used only
while the demand alone (no carry) leaves the bank axis short by more than rounding to its finest
jet explains: a demand one pattern nearly delivers needs no carry (the attitude loop integrates
the quantisation itself; carrying that too fires jets for every sub-quantum demand: case 1, 4 x
the pulses and +42 % propellant for no tracking gain), and such cycles cost one solve as before.
A short cycle costs two: the demand alone (the verdict), then with the carry (the answer flown).
The verdict is the demand's, not the carried answer's: a carried answer that happens to meet the
bank demand still spills, and that spill must be carried on. Reset when the health (the
allocator's tables) changes.
"""
from __future__ import annotations

import numpy as np


class ShortfallCarry:
    """The carry of one allocator (arrays preallocated; no allocation per cycle)."""

    def __init__(self, bank_axis_B: np.ndarray, torque_matrix_Nm: np.ndarray) -> None:
        self.axis = np.asarray(bank_axis_B, dtype=float).copy()
        inc = np.abs(self.axis @ np.asarray(torque_matrix_Nm, dtype=float))
        # the bank shortfall that rounding to the finest jet explains: half its increment
        self.round_Nm = 0.5 * float(np.min(inc[inc > 0.0]))
        self.carry_B = np.zeros(3)      # carried to the next demand [N m]
        self.demand_B = np.zeros(3)     # the demand the answer flown was solved for [N m]

    def _short(self, u_B: np.ndarray, tau_B: np.ndarray) -> bool:
        a = self.axis
        d = a[0] * u_B[0] + a[1] * u_B[1] + a[2] * u_B[2]
        got = a[0] * tau_B[0] + a[1] * tau_B[1] + a[2] * tau_B[2]
        return ((d - got) if d >= 0.0 else (got - d)) > self.round_Nm

    def solve(self, allocator, u_B: np.ndarray) -> np.ndarray:
        """The allocator's answer (its jets array) for demand ``u_B`` [N m] with the carry;
        ``allocator.tau_B`` etc. are those of the answer, ``demand_B`` what it was solved for."""
        jets = allocator.solve(u_B)
        self.demand_B[:] = u_B
        if allocator.rejected or not self._short(u_B, allocator.tau_B):
            self.carry_B[:] = 0.0
            return jets
        if self.carry_B[0] != 0.0 or self.carry_B[1] != 0.0 or self.carry_B[2] != 0.0:
            np.add(u_B, self.carry_B, out=self.demand_B)
            jets = allocator.solve(self.demand_B)
        np.subtract(self.demand_B, allocator.tau_B, out=self.carry_B)
        np.clip(self.carry_B, -allocator.carry_max, allocator.carry_max, out=self.carry_B)
        return jets

    def reset(self) -> None:
        self.carry_B[:] = 0.0
