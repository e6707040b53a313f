"""The SDOF transducer (paper eqs. 6-7): energy balance, brute force, trends, gradients."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import idtool


def vt_for(p, vr):
    """Sliding speed giving velocity ratio ~vr for the friction-free amplitude."""
    return vr * float(p.linear_amplitude_m * p.angular_frequency_rad_s)


def _steady_one(p, vr, steps_per_period):
    vt = vr * p.linear_amplitude_m * p.angular_frequency_rad_s
    return idtool.transducer_steady_state(p, vt, steps_per_period=steps_per_period)


# one compiled program: op by op, each loop of the shooting compiles on its own. Made
# once, at module level, so every call of the same shape runs the same program (a jit
# of a closure made inside steady_many was compiled anew at each call: 3 x ~10 s).
_steady_grid = jax.jit(
    jax.vmap(jax.vmap(_steady_one, (None, 0, None)), (0, None, None)), static_argnums=2
)


def steady_many(models, vrs, steps_per_period=256):
    """Steady states for a list of transducers at target velocity ratios (vectorised)."""
    batch = jax.tree.map(lambda *xs: jnp.stack([jnp.asarray(x, float) for x in xs]), *models)
    return _steady_grid(batch, jnp.asarray(vrs, float), steps_per_period)


def test_table2_preset():
    p = idtool.table2()
    assert float(p.mass_kg) == 0.02 and float(p.stiffness_n_m) == 133e6
    assert float(p.angular_frequency_rad_s) == pytest.approx(2 * np.pi * 60e3)
    assert float(p.contact_stiffness_n_m) == 0.056e6 and float(p.friction_coefficient) == 0.1
    assert float(p.damping_ratio) == 0.0  # the paper's undamped case
    assert float(p.fc_n) == pytest.approx(0.1 * 0.02 * 9.81)


@pytest.fixture(scope="module")
def table2_states():
    models = [
        idtool.table2(),
        idtool.table2(damping_ratio=0.02),
        idtool.table2(stiffness_n_m=2.4e9),
    ]
    return steady_many(models, [0.05, 0.3, 0.6, 0.9, 1.1])


def test_periodic_orbit_is_found(table2_states):
    assert float(jnp.max(table2_states.periodicity_error)) < 1e-9


def test_energy_balance_closes(table2_states):
    """PDR = 1 + phi_iu - phi_su (eq. 25) within 1e-3 of the input, 1 + phi_iu (eq. 22)."""
    b = table2_states.balance
    rel = np.abs(np.asarray(b.balance_residual)) / (1.0 + np.abs(np.asarray(b.input_power_ratio)))
    assert rel.max() < 1e-3
    assert np.max(np.asarray(b.input_power_ratio)) > 1.0  # a real ultrasonic input was there


def test_velocity_ratio_is_the_vibration_velocity_ratio(table2_states):
    # Friction barely changes the vibration in Table 2 (Fc = 0.02 N against Fe = 1920 N).
    np.testing.assert_allclose(
        table2_states.velocity_ratio, np.broadcast_to([0.05, 0.3, 0.6, 0.9, 1.1], (3, 5)), rtol=1e-4
    )


def test_no_reduction_without_reversal(table2_states):
    np.testing.assert_allclose(table2_states.friction_ratio[:, -1], 1.0, atol=1e-9)


def test_matches_prescribed_contact_when_friction_is_small():
    """With Fc << Fe the mass moves sinusoidally, so the SDOF friction ratio must equal
    the prescribed-vibration Dahl contact at the same VR and Lambda = Kt X / Fc."""
    p = idtool.table2()
    for vr in (0.2, 0.6):
        st = idtool.transducer_steady_state(p, vt_for(p, vr))
        x = float(st.vibration_velocity_m_s / p.angular_frequency_rad_s)
        law = idtool.Dahl(fc_n=float(p.fc_n), kt_n_m=float(p.contact_stiffness_n_m))
        ref = idtool.prescribed_cycle_average(
            law,
            float(st.vibration_velocity_m_s * st.velocity_ratio),
            x,
            float(p.angular_frequency_rad_s),
            n_phase=2048,
        )
        assert float(st.friction_ratio) == pytest.approx(float(ref.friction_ratio), abs=2e-4)


def test_brute_force_one_period_from_the_periodic_state():
    """LSODA on the raw eqs. 6-7 (sgn included), started on the computed orbit."""
    p = idtool.table2(force_amplitude_n=960.0, friction_coefficient=0.4, mass_kg=0.04)
    vt = vt_for(p, 0.4)
    st = idtool.transducer_steady_state(p, vt)
    m, ks, w, fe = 0.04, 133e6, 2 * np.pi * 60e3, 960.0
    kt, fc = 0.056e6, 0.4 * 0.04 * 9.81

    def rhs(t, y):
        x, xd, f, _ = y
        v = vt - xd
        return [xd, (-ks * x + fe * np.cos(w * t) + f) / m, kt * v * (1 - np.sign(v) * f / fc), f]

    period = 2 * np.pi / w
    y0 = [*np.asarray(st.state), 0.0]
    sol = solve_ivp(
        rhs, [0, period], y0, method="LSODA", rtol=1e-11, atol=1e-16, max_step=period / 2000
    )
    end = sol.y[:, -1]
    assert end[3] / (fc * period) == pytest.approx(float(st.friction_ratio), abs=1e-5)
    scale = np.array([float(p.linear_amplitude_m), float(p.linear_amplitude_m) * w, fc])
    np.testing.assert_allclose(end[:3] / scale, np.asarray(st.state) / scale, atol=1e-5)


def test_fourth_order_convergence_in_steps():
    """Against 256 steps per period, the program the other tests here run (a step count
    is a program of its own: 6 CPU s to compile): its own error, 8e-10, is 1/300 of
    ``e64`` (against 512 steps: e64 2.369e-7, e32 / e64 14.48; against 256: 2.361e-7,
    14.53)."""
    p = idtool.table2()
    vt = vt_for(p, 0.3)
    # 256 by default, not by keyword: jit keys its programs on the keywords passed, so
    # ``steps_per_period=256`` would compile the default's program a second time (4.4 s)
    fr = [
        float(idtool.transducer_steady_state(p, vt, steps_per_period=n).friction_ratio)
        for n in (32, 64)
    ] + [float(idtool.transducer_steady_state(p, vt).friction_ratio)]
    e32, e64 = abs(fr[0] - fr[2]), abs(fr[1] - fr[2])
    assert e64 < 1e-6
    assert e32 / e64 > 10  # fourth order would be 16; the reversal split keeps it high


def test_paper_trends_at_fixed_velocity_ratio():
    """Section 3.6: FR falls with Fe, rises with mu and with m; PDR rises with Fe. At
    VR 0.2, 0.5 and 0.8, in the batch shape of ``table2_states`` (3 transducers x 5
    ratios: one compiled program for both; the last two ratios are not read)."""
    vrs = [0.2, 0.5, 0.8, 0.2, 0.2]
    fe = steady_many([idtool.table2(force_amplitude_n=f) for f in (480.0, 960.0, 1920.0)], vrs)
    mu = steady_many([idtool.table2(friction_coefficient=u) for u in (0.05, 0.1, 0.4)], vrs)
    mass = steady_many([idtool.table2(mass_kg=m) for m in (0.01, 0.02, 0.08)], vrs)
    read = slice(0, 3)
    assert np.all(np.diff(np.asarray(fe.friction_ratio)[:, read], axis=0) < 0)
    assert np.all(np.diff(np.asarray(fe.power_ratio)[:, read], axis=0) > 0)
    assert np.all(np.diff(np.asarray(mu.friction_ratio)[:, read], axis=0) > 0)
    assert np.all(np.diff(np.asarray(mass.friction_ratio)[:, read], axis=0) > 0)


def test_march_from_rest_reaches_the_damped_orbit_and_balances():
    """The paper's procedure (RK4 from rest) with damping settles on the shooting orbit;
    undamped, the free oscillation stays but the window balance still closes."""
    damped = idtool.table2(damping_ratio=0.1)  # free oscillation decays by e^-27 in 200 periods
    vt = vt_for(damped, 0.5)
    run = idtool.simulate_transducer(damped, vt, periods=200, steps_per_period=256)
    st = idtool.transducer_steady_state(damped, vt)
    assert float(run.last_period.friction_ratio) == pytest.approx(
        float(st.friction_ratio), abs=1e-4
    )

    paper = idtool.table2()
    run = idtool.simulate_transducer(paper, vt_for(paper, 0.5), periods=20, steps_per_period=1000)
    b = run.last_period
    assert abs(float(b.stored_power_ratio)) > 1e-3  # the undecayed free oscillation
    assert abs(float(b.balance_residual)) < 1e-3 * (1.0 + abs(float(b.input_power_ratio)))


def _fr_of(params):
    kt, mu, fe = params
    p = idtool.table2(contact_stiffness_n_m=kt, friction_coefficient=mu, force_amplitude_n=fe)
    return idtool.transducer_steady_state(p, 0.1).friction_ratio


def test_gradients_match_central_differences():
    x = jnp.array([0.056e6, 0.1, 1920.0])
    # the gradient and the differences' values from the same function; not wrapped in a
    # jit of its own: JAX splits the jitted transducer_steady_state into its forward and
    # transposed programs, which compile in less (this test: 17.3 -> 16.0 CPU s)
    value_and_grad = jax.value_and_grad(_fr_of)
    grad = np.asarray(value_and_grad(x)[1])

    def f(z):
        return value_and_grad(z)[0]

    for i in range(3):
        h = 1e-5 * float(x[i])
        fd = (float(f(x.at[i].add(h))) - float(f(x.at[i].add(-h)))) / (2 * h)
        assert grad[i] == pytest.approx(fd, rel=1e-4), f"parameter {i}"
