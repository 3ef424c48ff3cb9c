"""The flight software counts and reports cycles whose allocated torque about the bank axis
(the velocity direction at trim) falls well short of SAMI's demand: the shortfall the sign
box hid (an allocator answer inside its box is not "degraded", yet may deliver nothing)."""
import numpy as np

from common.model import load_scenario
from fsw.flightsoftware import FlightSoftware, bank_short


def _fsw():
    return FlightSoftware(load_scenario("nominal"))


def _judge(fsw, t_s: float) -> None:
    """The cycle's verdict on its demand and allocated torque (the rule finish_cycle applies), noted."""
    fsw._check_bank_shortfall(t_s, bank_short(fsw.bank_axis_B, fsw.u_cal_B, fsw.tau_alloc_B, fsw._bank_short_min_Nm,
                                              fsw.params["control.shortfall_frac"]))


def test_a_cycle_short_on_the_bank_axis_is_counted_and_reported():
    fsw = _fsw()
    try:
        ax = fsw.bank_axis_B
        assert np.isclose(np.linalg.norm(ax), 1.0) and ax[0] > 0.9     # ~body x, tilted by the trim alpha
        fsw.u_cal_B[:] = [-2782.0, -24.0, -118.0]                         # a reversal's demand ...
        fsw.tau_alloc_B[:] = [-18.0, 0.0, 0.0]                            # ... and what the sign box gave
        _judge(fsw, 200.0)
        assert fsw.alloc_short and fsw.alloc_short_cycles == 1
        assert [e.code for e in fsw.events.history].count("alloc_short") == 1
        fsw.tau_alloc_B[:] = fsw.u_cal_B * 0.6                            # most of it delivered
        _judge(fsw, 200.02)
        assert not fsw.alloc_short and fsw.alloc_short_cycles == 1
    finally:
        fsw.close()


def test_quantisation_is_not_a_shortfall():
    fsw = _fsw()
    try:
        # under two of the largest single-jet bank-axis torques, getting nothing is quantisation
        fsw.u_cal_B[:] = 0.9 * fsw._bank_short_min_Nm * fsw.bank_axis_B
        fsw.tau_alloc_B[:] = 0.0
        _judge(fsw, 1.0)
        assert not fsw.alloc_short and fsw.alloc_short_cycles == 0
    finally:
        fsw.close()
