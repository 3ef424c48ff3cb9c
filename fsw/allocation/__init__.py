"""Fault-tolerant discrete control allocation (paper section 3).

model      the problem: health -> effective model, tolerances, problem checks
tables     candidate tables of a health configuration: the types, work buffers, build_tables
build      the table build's numba kernels (enumeration, octant tables, tree)
query      the solve kernels over one configuration's tables
allocator  the Allocator: parameters, table cache, switching, interim model
rebuild    the background table builder (real time)
dutycycle  the duty-cycle realisation while the bank axis is short (an LP, a sigma-delta)
dutylp     that LP's compiled solver (a bounded dual simplex) and the sigma-delta's kernel
reference  HiGHS and enumeration solvers: test and benchmark references, not flown
"""
from .allocator import PARAMS, Allocator
from .model import effective_model

__all__ = ["PARAMS", "Allocator", "effective_model"]
