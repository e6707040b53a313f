"""Prescribed-vibration contact against closed forms and brute-force simulation (notes §4)."""

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import idtool
from idtool._model import _limits as limits


def cycle(law, vr, a=1.0, w=1.0, n_phase=256):
    """Dimensionless contact: v = VR a w."""
    return idtool.prescribed_cycle_average(law, vr * a * w, a, w, n_phase=n_phase)


def dahl(lam):
    return idtool.Dahl(fc_n=1.0, kt_n_m=lam)


def np_force_rate(kt, fc, fs=None, vs=1.0):
    """dF/dt of LuGre/Dahl written afresh in NumPy (independent of idtool._model._laws)."""
    fs = fc if fs is None else fs

    def rate(f, v):
        level = fc + (fs - fc) * np.exp(-((v / vs) ** 2))
        return kt * v * (1.0 - np.sign(v) * f / level)

    return rate


def brute_force(rate, vr, cycles=8, integrand=lambda f, v: f):
    """Time-march the bristle ODE with LSODA (rtol 1e-10); last-cycle mean of ``integrand``.

    Independent of the affine phase-grid solver: it integrates dF/dt with the sgn in
    it, from F = 0, for long enough that the transient has died (a = w = 1).
    """

    def rhs(th, y):
        v = vr + np.cos(th)
        return [rate(y[0], v), integrand(y[0], v)]

    t1, t2 = 2 * np.pi * (cycles - 1), 2 * np.pi * cycles
    sol = solve_ivp(
        rhs,
        [0, t2],
        [0.0, 0.0],
        method="LSODA",
        rtol=1e-10,
        atol=1e-12,
        max_step=0.02,
        dense_output=True,
    )
    return (sol.sol(t2)[1] - sol.sol(t1)[1]) / (2 * np.pi)


@pytest.mark.parametrize("vr", np.linspace(0.05, 0.95, 19))
def test_coulomb_matches_arcsine_law(vr):
    fr = cycle(idtool.Coulomb(fc_n=1.0), vr).friction_ratio
    assert abs(float(fr) - 2 / np.pi * np.arcsin(vr)) < 1e-3


def test_coulomb_power_ratio_closed_form():
    vr = np.linspace(0.05, 0.95, 10)
    got = jax.vmap(lambda v: cycle(idtool.Coulomb(fc_n=1.0), v).power_ratio)(vr)
    np.testing.assert_allclose(got, limits.coulomb_power_ratio(vr), rtol=1e-9)


@pytest.mark.parametrize(
    "law",
    [
        idtool.Coulomb(fc_n=2.0),
        idtool.Dahl(fc_n=2.0, kt_n_m=3.0),
        idtool.Dahl(fc_n=2.0, kt_n_m=300.0),
        idtool.LuGre(fc_n=2.0, kt_n_m=3.0, fs_n=2.0, vs_m_s=0.1),
    ],
)
@pytest.mark.parametrize("vr", [1.0, 1.3, 4.0])
def test_no_reversal_means_no_reduction(law, vr):
    out = cycle(law, vr)
    assert abs(float(out.friction_ratio) - 1.0) < 1e-12


def test_zero_amplitude_is_plain_sliding():
    out = idtool.prescribed_cycle_average(dahl(3.0), 0.02, 0.0, 1.0)
    assert float(out.friction_ratio) == pytest.approx(1.0, abs=1e-12)
    assert float(out.power_ratio) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize(
    ("vr", "lam", "expected"),
    [(0.1, 1, 0.122), (0.5, 1, 0.600), (0.5, 5, 0.379), (0.9, 2, 0.946), (0.3, 100, 0.195)],
)
def test_dahl_spot_values_from_notes(vr, lam, expected):
    # The notes give three decimals, so 2e-3 is their rounding plus our tolerance.
    assert abs(float(cycle(dahl(lam), vr).friction_ratio) - expected) < 2e-3


@pytest.mark.parametrize(("vr", "lam"), [(0.1, 1.0), (0.5, 5.0), (0.9, 2.0), (0.3, 100.0)])
def test_dahl_matches_brute_force_time_marching(vr, lam):
    # LSODA at rtol 1e-10 is good to ~1e-7 here; 256 phase steps are within 5e-5
    # even at Lambda = 100 (second-order convergence, see test below).
    assert float(cycle(dahl(lam), vr).friction_ratio) == pytest.approx(
        brute_force(np_force_rate(lam, 1.0), vr), abs=5e-5
    )


def test_lugre_with_stribeck_matches_brute_force():
    law = idtool.LuGre(fc_n=1.0, kt_n_m=5.0, fs_n=1.5, vs_m_s=0.2)
    for vr in (0.2, 0.6):
        got = float(cycle(law, vr).mean_friction_n)
        ref = brute_force(np_force_rate(5.0, 1.0, fs=1.5, vs=0.2), vr)
        assert got == pytest.approx(ref, abs=2e-4)


def test_phase_grid_converges_at_second_order():
    errs = []
    ref = float(cycle(dahl(100.0), 0.3, n_phase=8192).friction_ratio)
    for n in (64, 128, 256):
        errs.append(abs(float(cycle(dahl(100.0), 0.3, n_phase=n).friction_ratio) - ref))
    assert errs[2] < 5e-5
    assert 3.0 < errs[0] / errs[1] < 5.0 and 3.0 < errs[1] / errs[2] < 5.0


def test_dahl_tends_to_coulomb_as_lambda_grows():
    vr = 0.4
    coulomb = float(limits.coulomb_friction_ratio(vr))
    gaps = [
        float(cycle(dahl(lam), vr, n_phase=2048).friction_ratio) - coulomb
        for lam in (10, 100, 1000, 10000)
    ]
    assert all(g > 0 for g in gaps)
    assert all(later < earlier for earlier, later in itertools.pairwise(gaps))
    assert gaps[-1] < 2e-3


@pytest.mark.parametrize("vr", [0.05, 0.3, 0.7, 0.95])
def test_dahl_small_lambda_limit(vr):
    small = float(cycle(dahl(1e-3), vr).friction_ratio)
    assert small == pytest.approx(float(limits.dahl_small_lambda_friction_ratio(vr)), abs=1e-3)


def test_dahl_creeps_below_presliding_length():
    # Lambda < 1: amplitude below Fc/Kt still lowers friction, about (pi/2) VR.
    fr = float(cycle(dahl(0.01), 0.05).friction_ratio)
    assert fr == pytest.approx(np.pi / 2 * 0.05, rel=0.01)


@pytest.mark.parametrize("vr", [0.2, 0.5, 0.8])
def test_lugre_reduces_to_dahl(vr):
    lugre = idtool.LuGre(fc_n=1.3, kt_n_m=4.0, fs_n=1.3, vs_m_s=0.05, s1_n_s_m=0.0, s2_n_s_m=0.0)
    a, b = cycle(lugre, vr), cycle(idtool.Dahl(fc_n=1.3, kt_n_m=4.0), vr)
    assert float(a.friction_ratio) == pytest.approx(float(b.friction_ratio), abs=1e-12)
    assert float(a.power_ratio) == pytest.approx(float(b.power_ratio), abs=1e-12)


@pytest.mark.parametrize(("vr", "lam"), [(0.2, 0.5), (0.5, 3.0), (0.8, 30.0)])
def test_dahl_energy_balance(vr, lam):
    """Mean friction power = mean dissipation |V| F^2 / Fc (elastic energy is periodic).

    For Dahl, F V = d/dt(F^2 / 2Kt) + |V| F^2 / Fc; the first term averages to zero over
    a cycle. Computed here by brute-force quadrature of the LSODA trajectory, against
    the solver's power ratio; also PDR = FR + phi_iu.
    """
    out = cycle(dahl(lam), vr)
    dissipated = brute_force(
        np_force_rate(lam, 1.0), vr, cycles=10, integrand=lambda f, v: abs(v) * f * f
    )
    pdr = float(out.power_ratio)
    assert pdr == pytest.approx(dissipated / vr, rel=1e-3)
    assert pdr == pytest.approx(float(out.friction_ratio + out.input_power_ratio), abs=1e-12)


def test_bristle_damping_adds_dissipation_not_mean_force():
    base = idtool.LuGre(fc_n=1.0, kt_n_m=5.0, fs_n=1.2, vs_m_s=0.1)
    damped = idtool.LuGre(fc_n=1.0, kt_n_m=5.0, fs_n=1.2, vs_m_s=0.1, s1_n_s_m=0.5)
    a, b = cycle(base, 0.4), cycle(damped, 0.4)
    assert float(a.friction_ratio) == pytest.approx(float(b.friction_ratio), abs=1e-12)
    assert float(b.power_ratio) > float(a.power_ratio)


def _physical_fr(params):
    kt, mu, amp, speed = params
    law = idtool.Dahl(fc_n=mu * 450.0, kt_n_m=kt)
    return idtool.prescribed_cycle_average(law, speed, amp, 2 * np.pi * 20e3).friction_ratio


@pytest.mark.parametrize("speed", [0.025, 0.05])
def test_gradients_match_central_differences(speed):
    # Kt [N/m], mu, amplitude [m], sliding speed [m/s] at a bench-like operating point.
    x = jnp.array([1e9, 0.3, 4e-7, speed])
    grad = np.asarray(jax.grad(_physical_fr)(x))
    for i in range(4):
        h = 1e-5 * float(x[i])
        fd = (float(_physical_fr(x.at[i].add(h))) - float(_physical_fr(x.at[i].add(-h)))) / (2 * h)
        assert grad[i] == pytest.approx(fd, rel=1e-4), f"parameter {i}"
        assert abs(grad[i]) > 0


def test_jit_and_vmap_agree_with_plain_calls():
    law = dahl(3.0)
    vrs = jnp.linspace(0.05, 1.2, 7)
    batched = jax.vmap(lambda v: cycle(law, v).friction_ratio)(vrs)
    jitted = jax.jit(lambda v: cycle(law, v).friction_ratio)
    for v, b in zip(vrs, batched, strict=True):
        plain = cycle(law, float(v)).friction_ratio
        assert float(plain) == pytest.approx(float(b), abs=1e-14)
        assert float(plain) == pytest.approx(float(jitted(v)), abs=1e-14)


def test_perpendicular_limit_never_reaches_one():
    vr = np.array([0.5, 1.0, 3.0, 30.0])
    fr = np.asarray(limits.coulomb_perpendicular_friction_ratio(vr))
    assert np.all(np.diff(fr) > 0) and np.all(fr < 1.0)
    assert fr[-1] == pytest.approx(1.0, abs=1e-3)
