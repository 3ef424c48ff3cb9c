"""common/mrp.py kernels (the ones the plant, guidance and control fly) against independent
truth: the matrix forms written from the definitions, DCM products, and round trips."""
from __future__ import annotations

import numpy as np
import pytest

from common import mrp

RNG = np.random.default_rng(11)
SIGMAS = [RNG.normal(size=3) * sc for sc in (0.01, 0.3, 0.9, 2.0) for _ in range(25)]


def _dcm_reference(s):
    """C = I + (8 [s x]^2 - 4 (1 - s.s) [s x]) / (1 + s.s)^2 with NumPy matrices."""
    S = mrp.tilde(s)
    s2 = s @ s
    return np.eye(3) + (8.0 * S @ S - 4.0 * (1.0 - s2) * S) / (1.0 + s2) ** 2


@pytest.mark.parametrize("s", SIGMAS)
def test_both_dcm_forms_match_the_definition_and_are_rotations(s):
    C = np.empty((3, 3))
    mrp.dcm_into(s[0], s[1], s[2], C)
    for M in (C, mrp.to_dcm(s)):
        assert np.allclose(M, _dcm_reference(s), atol=1e-13)
        assert np.allclose(M @ M.T, np.eye(3), atol=1e-13) and np.isclose(np.linalg.det(M), 1.0)


@pytest.mark.parametrize("s", SIGMAS)
def test_from_dcm_inverts_to_dcm_on_the_short_set(s):
    short = mrp.switch_shadow(s)
    assert np.linalg.norm(short) <= 1.0 + 1e-12
    assert np.allclose(mrp.to_dcm(short), mrp.to_dcm(s), atol=1e-13)     # same attitude
    assert np.allclose(mrp.from_dcm(mrp.to_dcm(s)), short, atol=1e-12)
    q = mrp.dcm_to_quat(mrp.to_dcm(s))
    assert np.allclose(q, mrp.sigma_to_quat(short), atol=1e-12) and q[0] >= 0.0


@pytest.mark.parametrize("s", SIGMAS[::5])
def test_kinematics_kernels_equal_the_matrix_forms(s):
    w, dw = RNG.normal(size=3), RNG.normal(size=3)
    out, sd, sdd, back = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    mrp.B_mul(s, w, out)
    assert np.allclose(out, mrp.B_matrix(s) @ w, atol=1e-12)
    mrp.sigma_dot_into(s, w, sd)
    assert np.allclose(sd, mrp.sigma_dot(s, w), atol=1e-12)
    mrp.Bdot_mul(s, sd, w, out)
    assert np.allclose(out, mrp.B_dot(s, sd) @ w, atol=1e-12)
    mrp.sigma_derivatives(s, w, dw, sd, sdd)
    assert np.allclose(sdd, 0.25 * (mrp.B_dot(s, sd) @ w + mrp.B_matrix(s) @ dw), atol=1e-12)
    mrp.omega_from_sigma_dot_into(s, sd, back)
    assert np.allclose(back, w, atol=1e-10)


@pytest.mark.parametrize("s", SIGMAS[::5])
def test_compose_is_the_dcm_product(s):
    d = RNG.normal(size=3) * 0.05
    m = np.array(mrp.compose(d[0], d[1], d[2], s[0], s[1], s[2]))
    assert np.allclose(mrp.to_dcm(m), mrp.to_dcm(d) @ mrp.to_dcm(s), atol=1e-12)
    short = np.array(mrp.shadow_switched(*m))
    assert np.linalg.norm(short) <= 1.0 + 1e-12 and np.allclose(mrp.to_dcm(short), mrp.to_dcm(m), atol=1e-12)
