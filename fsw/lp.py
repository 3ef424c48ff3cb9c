"""Linear-programming helpers over HiGHS, shared by the controllability LP (fsw/controllability.py)
and the allocation problem's reference solver (fsw/allocation/reference.py)."""
from __future__ import annotations

import numpy as np


def set_colwise_matrix(lp, M: np.ndarray) -> None:
    """Store the dense constraint matrix M (rows x columns) in ``lp`` (a highspy.HighsLp)
    column-wise, with its nonzeros only."""
    import highspy
    start, index, value = [0], [], []
    for j in range(M.shape[1]):
        nz = np.flatnonzero(M[:, j])
        index.extend(nz.tolist())
        value.extend(M[nz, j].tolist())
        start.append(len(index))
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.start_ = np.array(start, dtype=np.int32)
    lp.a_matrix_.index_ = np.array(index, dtype=np.int32)
    lp.a_matrix_.value_ = np.array(value, dtype=float)


def solve_or_none(h, lp) -> np.ndarray | None:
    """Pass ``lp`` to the highspy.Highs ``h`` and run it: the primal column values at the optimum,
    None if the problem is infeasible; any other status is an error."""
    import highspy
    h.passModel(lp)
    h.run()
    status = h.getModelStatus()
    if status == highspy.HighsModelStatus.kInfeasible:
        return None
    if status != highspy.HighsModelStatus.kOptimal:
        raise RuntimeError(f"HiGHS: unexpected status {h.modelStatusToString(status)}")
    return np.asarray(h.getSolution().col_value)
