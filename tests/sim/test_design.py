"""Sliding-mode design tools against the numbers printed in seed section 2.2.

Every printed number is compared to its printed precision: ``|computed -
printed| <= half a unit in the last printed digit`` (``HALF_ULP``).
"""

from __future__ import annotations

import numpy as np
import pytest

from sim.boundary_layer import DynamicBoundaryLayer, sat, static_boundary_layer
from sim.design import equivalent_control_gain, lq_sliding_surface, lqr_gain, regular_form
from sim.scenarios.pendulum import NOMINAL, Q_WEIGHT, R_WEIGHT, linear_model, nonlinear_derivative, smc_design

HALF_ULP_4 = 0.5e-4 + 1e-12  # four printed decimals (1e-12: binary round-off of ties like 28.60375)
HALF_ULP_1 = 0.5e-1 + 1e-12  # one printed decimal

# seed section 2.2, printed numeric state equation (tau = 0)
PRINTED_A = np.array(
    [
        [0, 0, 1, 0],
        [0, 0, 0, 1],
        [0, -1.6345, -2, 0.0042],
        [0, 28.6037, 5, -0.0729],
    ]
)
PRINTED_B = np.array([0, 0, 0.3333, -0.8333])

# seed section 2.2, printed T_r.  The OCR kept magnitudes but dropped signs in
# rows 2 and 3 ("0 371 4 0 0.8 621 0.34 448"); row 4 kept its signs.
PRINTED_TR_ABS = np.array(
    [
        [0, 1, 0, 0],
        [0.3714, 0, 0.8621, 0.3448],
        [0.9285, 0, 0.3448, 0.1379],
        [0, 0, 0.3714, 0.9285],
    ]
)
PRINTED_TR_ROW4 = np.array([0, 0, -0.3714, 0.9285])

# seed section 2.2, printed regular-form A_reg and B_reg
PRINTED_A_REG = np.array(
    [
        [0, 0.3448, 0.1379, 0.9285],
        [8.4543, -0.3276, -0.1310, 0.1179],
        [3.3817, 0.7974, 0.3190, -0.3528],
        [27.1650, 4.6185, 1.8474, -2.0643],
    ]
)
PRINTED_B_REG = np.array([0, 0, 0, -0.8975])

# seed section 2.2, printed S "3.1632 10.1219 2.7436 2.1745".  The first entry
# is printed with two digits transposed: the design gives sqrt(10) = 3.16228,
# and the printed U_eq (below) is only reproduced with S[0] = 3.1623 (3.1632
# would give U_eq[2] = 9.5243, not the printed 9.5233); see test_printed_S_first_entry.
PRINTED_S = np.array([3.1623, 10.1219, 2.7436, 2.1745])
PRINTED_S_AS_OCRD = np.array([3.1632, 10.1219, 2.7436, 2.1745])
# seed section 2.2, printed U_eq
PRINTED_U_EQ = np.array([0, 64.3035, 9.5233, 11.1136])
# seed section 2.2, printed K_LQR (u = -K x, MATLAB lqr sign)
PRINTED_K_LQR = np.array([-31.6, -179.1, -38.7, -35.8])


@pytest.fixture(scope="module")
def plant() -> tuple[np.ndarray, np.ndarray]:
    A, B = linear_model(NOMINAL)
    return A, B[:, :1]


def test_linear_model_reproduces_printed_A_and_B(plant):
    A, B = plant
    assert np.all(np.abs(A - PRINTED_A) <= HALF_ULP_4)
    assert np.all(np.abs(B[:, 0] - PRINTED_B) <= HALF_ULP_4)


@pytest.mark.parametrize("g", [9.81, 9.80665])
def test_other_gravity_values_do_not_reproduce_printed_A(g):
    from dataclasses import replace

    A, _ = linear_model(replace(NOMINAL, g=g))
    assert np.max(np.abs(A - PRINTED_A)) > HALF_ULP_4


def test_nonlinear_model_linearises_to_linear_model():
    A, B = linear_model(NOMINAL)
    z0 = np.zeros(4)
    h = 1e-6
    jac = np.column_stack(
        [(nonlinear_derivative(NOMINAL, z0 + h * e, 0.0) - nonlinear_derivative(NOMINAL, z0 - h * e, 0.0)) / (2 * h) for e in np.eye(4)]
    )
    ju = (nonlinear_derivative(NOMINAL, z0, h) - nonlinear_derivative(NOMINAL, z0, -h)) / (2 * h)
    jt = (nonlinear_derivative(NOMINAL, z0, 0.0, h) - nonlinear_derivative(NOMINAL, z0, 0.0, -h)) / (2 * h)
    np.testing.assert_allclose(jac, A, atol=1e-6)
    np.testing.assert_allclose(np.column_stack([ju, jt]), B, atol=1e-6)


def test_regular_form_reproduces_printed_Tr_and_matrices(plant):
    A, B = plant
    rf = regular_form(A, B)
    np.testing.assert_allclose(rf.T_r @ rf.T_r.T, np.eye(4), atol=1e-12)
    assert np.all(np.abs(np.abs(rf.T_r) - PRINTED_TR_ABS) <= HALF_ULP_4)
    assert np.all(np.abs(rf.T_r[3] - PRINTED_TR_ROW4) <= HALF_ULP_4)
    assert np.all(np.abs(rf.A - PRINTED_A_REG) <= HALF_ULP_4)
    assert np.all(np.abs(rf.B[:, 0] - PRINTED_B_REG) <= HALF_ULP_4)
    assert rf.B2.shape == (1, 1) and rf.A11.shape == (3, 3) and rf.A12.shape == (3, 1)


def test_regular_form_of_a_multi_input_plant_zeroes_the_top_of_B():
    rng = np.random.default_rng(1)
    A, B = rng.normal(size=(5, 5)), rng.normal(size=(5, 2))
    rf = regular_form(A, B)
    np.testing.assert_allclose(rf.T_r @ B, rf.B, atol=1e-12)
    assert np.all(rf.B[:3] == 0.0)
    assert abs(np.linalg.det(rf.B2)) > 1e-6


def test_lq_sliding_surface_reproduces_printed_S(plant):
    A, B = plant
    S = lq_sliding_surface(A, B, Q_WEIGHT)
    assert S.shape == (1, 4)
    assert np.all(np.abs(S[0] - PRINTED_S) <= HALF_ULP_4)
    # S2 = I in regular-form coordinates, so S B = B2 (-0.8975 printed)
    assert abs((S @ B)[0, 0] - PRINTED_B_REG[3]) <= HALF_ULP_4


def test_printed_S_first_entry_is_a_digit_transposition(plant):
    A, B = plant
    S_ocr = PRINTED_S_AS_OCRD[None, :]
    u_eq_from_ocr = equivalent_control_gain(A, B, S_ocr)[0]
    assert abs(u_eq_from_ocr[2] - PRINTED_U_EQ[2]) > 5 * HALF_ULP_4
    u_eq_from_fixed = equivalent_control_gain(A, B, PRINTED_S[None, :])[0]
    assert abs(u_eq_from_fixed[2] - PRINTED_U_EQ[2]) <= 2e-4  # S itself is rounded to 4 decimals


def test_sliding_motion_is_stable(plant):
    A, B = plant
    S = lq_sliding_surface(A, B, Q_WEIGHT)
    K_eq = equivalent_control_gain(A, B, S)
    eig = np.linalg.eigvals(A + B @ K_eq)
    # one eigenvalue at zero (the sigma direction, left free by u_eq), the rest stable (Eq 2.44)
    eig = eig[np.argsort(np.abs(eig))]
    assert abs(eig[0]) < 1e-9
    assert np.all(eig[1:].real < 0)
    np.testing.assert_allclose(S @ (A + B @ K_eq), 0.0, atol=1e-9)  # sigma' = 0 under u_eq (Eq 2.15)


def test_equivalent_control_reproduces_printed_U_eq(plant):
    A, B = plant
    K_eq = equivalent_control_gain(A, B, lq_sliding_surface(A, B, Q_WEIGHT))
    assert np.all(np.abs(K_eq[0] - PRINTED_U_EQ) <= HALF_ULP_4)


def test_lqr_reproduces_printed_gains(plant):
    A, B = plant
    K = lqr_gain(A, B, Q_WEIGHT, R_WEIGHT)
    assert np.all(np.abs(K[0] - PRINTED_K_LQR) <= HALF_ULP_1)
    assert np.all(np.linalg.eigvals(A - B @ K).real < 0)


def test_smc_design_bundles_the_same_numbers():
    d = smc_design()
    assert np.all(np.abs(d.S - PRINTED_S) <= HALF_ULP_4)
    assert np.all(np.abs(d.K_eq - PRINTED_U_EQ) <= HALF_ULP_4)
    assert np.all(np.abs(d.K_lqr - PRINTED_K_LQR) <= HALF_ULP_1)


def test_design_rejects_bad_shapes():
    with pytest.raises(ValueError, match="square"):
        regular_form(np.ones((3, 2)), np.ones((3, 1)))
    with pytest.raises(ValueError, match="rows"):
        regular_form(np.eye(3), np.ones((2, 1)))
    with pytest.raises(ValueError, match="rank"):
        regular_form(np.eye(3), np.ones((3, 2)))


# ---------------------------------------------------------------- boundary layers


def test_static_boundary_layer_is_linear_inside_and_saturated_outside():
    np.testing.assert_allclose(static_boundary_layer(np.array([-1.0, -0.05, 0.0, 0.05, 1.0]), 50.0, 0.1), [-50, -25, 0, 25, 50])
    assert sat(3.0) == 1.0 and sat(-3.0) == -1.0
    with pytest.raises(ValueError, match="eps"):
        static_boundary_layer(1.0, 1.0, 0.0)


def _f16_layer() -> DynamicBoundaryLayer:
    # seed section 3.2.1: rho = -10, eps = 0.1, a_delta = 20, delta_max = 0.37 rad, rate 10 rad/s
    return DynamicBoundaryLayer(rho=-10.0, eps_min=0.1, a_delta=20.0, delta_max=0.37, rate_max=10.0)


def test_dynamic_layer_equals_static_layer_far_from_limits():
    bl = _f16_layer()
    v, eps = bl.command(sigma=0.05, delta=0.0)
    assert eps[0] == pytest.approx(0.1)
    assert v[0] == pytest.approx(float(static_boundary_layer(0.05, -10.0, 0.1)))


@pytest.mark.parametrize("sigma", [-50.0, -2.0, -0.3, 0.3, 2.0, 50.0])
@pytest.mark.parametrize("delta", [-0.37, -0.36, -0.2, 0.0, 0.2, 0.36, 0.37])
def test_dynamic_layer_respects_eqs_3_6_to_3_8(sigma, delta):
    bl = _f16_layer()
    v, eps = bl.command(sigma=sigma, delta=delta)
    assert abs(sigma) <= eps[0] + 1e-12  # Eq 3.6
    assert abs(delta + v[0] / 20.0) <= 0.37 + 1e-12  # Eq 3.7
    assert abs(v[0]) <= 10.0 + 1e-12  # Eq 3.8
    assert not bl.infeasible[0]
    # the layer is no wider than it needs to be: the binding constraint is active
    if eps[0] > max(0.1, abs(sigma)) + 1e-9:
        assert min(10.0 - abs(v[0]), 0.37 - abs(delta + v[0] / 20.0)) <= 1e-9


def test_dynamic_layer_flags_an_infeasible_equivalent_control():
    bl = _f16_layer()
    # v_eq alone breaks Eq 3.7 (delta + v/20 <= 0.37 needs v <= 7.4) and Eq 3.8 (v <= 10)
    v, _ = bl.command(sigma=0.0, delta=0.0, v_eq=15.0)
    assert bl.infeasible[0]
    assert v[0] == pytest.approx(7.4)
    v, _ = bl.command(sigma=0.0, delta=-0.3, v_eq=15.0)  # now only the rate limit binds
    assert bl.infeasible[0]
    assert v[0] == pytest.approx(10.0)
