"""An independent LP oracle the controllability tests share: the weaker bank way's authority
with a trim held, from scipy's LP (not the FSW's HiGHS model)."""
from __future__ import annotations

import numpy as np


def weak_way_truth(C, b, A, W, theta):
    """The weaker way's bank authority with trim theta held, from scipy's LP on the stacked
    inertia corners (an independent formulation of item 2/3: one duty-cycle set per corner)."""
    from scipy.optimize import linprog
    p, K = C.shape[1], W.shape[0]
    out = []
    for sg in (1.0, -1.0):
        Aeq = np.zeros((3 * K, K * p + 1))
        for k in range(K):
            Aeq[3 * k:3 * k + 3, k * p:(k + 1) * p] = C
            Aeq[3 * k:3 * k + 3, -1] = -W[k]
        c = np.zeros(K * p + 1)
        c[-1] = -sg
        res = linprog(c, A_eq=Aeq, b_eq=np.tile(-b - A @ theta, K), bounds=[(0, 1)] * (K * p) + [(None, None)],
                      method="highs")
        out.append(max(0.0, sg * res.x[-1]) if res.status == 0 else 0.0)
    return min(out)
