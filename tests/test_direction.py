"""Direction of vibration (issue 30, item 2): the transverse and normal contact kernels
against closed forms, limits and brute-force time marching; the default (along) bit for
bit what it was; the fit's choice recorded and read back."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares
from scipy.special import ellipk

import idtool
from idtool._data._schema import schema_validator
from idtool._errors import IdtoolError
from idtool._fit._artefact import _spec
from idtool._fit._folder import FIT_JSON
from idtool._model import _limits as limits
from idtool._model._bench import on_friction_ratio
from idtool._model._coupling import PowerLimitedCoupling
from idtool._model._direction_normal import KAPPA, _mean_indentation
from idtool._model._spec import ModelSpec

TWO_PI = 2.0 * np.pi


def transverse(law, xi, n_phase=256):
    """Dimensionless transverse contact: a = w = 1, v = xi."""
    return idtool.transverse_cycle_average(law, xi, 1.0, 1.0, n_phase=n_phase)


def closed_form(xi):
    """Coulomb, transverse: (2/pi) xi / sqrt(1 + xi^2) K(1 / (1 + xi^2)), SciPy's K(m)."""
    return 2.0 / np.pi * xi / np.sqrt(1.0 + xi**2) * ellipk(1.0 / (1.0 + xi**2))


def dahl(lam):
    return idtool.Dahl(fc_n=1.0, kt_n_m=lam)


# ------------------------------------------------------------------ transverse, Coulomb
def test_closed_form_convention_and_spot_values():
    # the parameter convention: K(m) = int dt / sqrt(1 - m sin^2 t); the closed form is
    # the cycle mean <xi / sqrt(xi^2 + cos^2)> by quadrature
    t = np.linspace(0.0, TWO_PI, 200_001)
    for xi in (0.1, 1.0):
        mean = np.trapezoid(xi / np.sqrt(xi**2 + np.cos(t) ** 2), t) / TWO_PI
        assert closed_form(xi) == pytest.approx(mean, abs=1e-12)
    assert closed_form(1.0) == pytest.approx(0.8346, abs=5e-5)
    assert closed_form(0.1) == pytest.approx(0.2344, abs=5e-5)
    xi = np.array([0.003, 0.01, 0.1, 1.0, 30.0])
    jnp_form = np.asarray(limits.coulomb_perpendicular_friction_ratio(xi))
    assert np.max(np.abs(jnp_form - closed_form(xi))) < 1e-14


@pytest.mark.parametrize("xi", [0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 30.0])
def test_coulomb_matches_the_elliptic_closed_form(xi):
    fr = float(transverse(idtool.Coulomb(fc_n=1.0), xi).friction_ratio)
    # measured: below 1e-15 at these xi (the grid sums a periodic analytic function)
    assert abs(fr - closed_form(xi)) < 1e-6
    assert abs(fr - closed_form(xi)) < 1e-12


def test_coulomb_power_is_the_mean_slip_speed():
    # Coulomb: F = Fc V / |V|, so the power is Fc <|V|>; PDR = <|V|> / v
    xi = 0.2
    c = transverse(idtool.Coulomb(fc_n=1.0), xi)
    t = np.linspace(0.0, TWO_PI, 400_001)
    speed = np.trapezoid(np.hypot(xi, np.cos(t)), t) / TWO_PI
    assert float(c.power_ratio) == pytest.approx(speed / xi, rel=1e-10)
    assert float(c.input_power_ratio) == pytest.approx(speed / xi - closed_form(xi), rel=1e-9)


# ------------------------------------------------------------------ transverse, limits
def test_stiff_dahl_tends_to_the_coulomb_closed_form():
    xi = 0.3
    errors = [
        abs(float(transverse(dahl(lam), xi).friction_ratio) - closed_form(xi))
        for lam in (1e2, 1e3, 1e4, 1e5, 1e6)
    ]
    assert np.all(np.diff(errors) < 0)
    assert errors[-1] < 1e-5


def test_small_amplitude_gives_plain_sliding():
    law = idtool.Dahl(fc_n=100.0, kt_n_m=1e8)
    v, w = 0.025, TWO_PI * 20e3
    at_rest = float(idtool.transverse_cycle_average(law, v, 0.0, w).friction_ratio)
    assert at_rest == pytest.approx(1.0, abs=1e-13)  # the grid's weights sum to pi
    frs = [
        float(idtool.transverse_cycle_average(law, v, a, w).friction_ratio)
        for a in (1e-6, 1e-7, 1e-8, 1e-9)
    ]
    assert np.all(np.diff(frs) > 0) and np.all(np.asarray(frs) < 1.0)
    assert 1.0 - frs[-1] < 1e-5
    # Coulomb at large xi: 1 - FR = 1 / (4 xi^2) to leading order
    xi = 100.0
    fr = float(transverse(idtool.Coulomb(fc_n=1.0), xi).friction_ratio)
    assert (1.0 - fr) * 4 * xi**2 == pytest.approx(1.0, rel=1e-3)


def test_transverse_reduces_friction_at_every_velocity_ratio():
    # unlike along (FR = 1 for VR >= 1), a transverse vibration always tilts the slip
    for law in (idtool.Coulomb(fc_n=1.0), dahl(3.0)):
        fr = np.array([float(transverse(law, xi).friction_ratio) for xi in (0.5, 1.0, 2.0, 5.0)])
        assert np.all(fr < 1.0) and np.all(np.diff(fr) > 0)


# ------------------------------------------------------------------ transverse, brute force
def brute_force_2d(lam, xi, fs_ratio=1.0, vs=1.0, s1=0.0, s2=0.0):
    """LSODA of the 2-D LuGre/Dahl ODE (a = w = Fc = 1), written afresh in NumPy:
    dz/dt = V - |V| z / g, g = (1 + (fs - 1) exp(-(|V|/vs)^2)) / lam, F = lam z + s1 dz/dt +
    s2 V; cycle after cycle until the mean force along x changes by less than 1e-11."""

    def rhs(t, y):
        vx, vy = xi, np.cos(t)
        speed = np.hypot(vx, vy)
        g = (1.0 + (fs_ratio - 1.0) * np.exp(-((speed / vs) ** 2))) / lam
        zdx = vx - speed * y[0] / g
        zdy = vy - speed * y[1] / g
        return [zdx, zdy, lam * y[0] + s1 * zdx + s2 * vx]

    y, prev = np.zeros(2), None
    for k in range(400):
        sol = solve_ivp(
            rhs,
            (TWO_PI * k, TWO_PI * (k + 1)),
            [y[0], y[1], 0.0],
            method="LSODA",
            rtol=1e-11,
            atol=1e-13,
        )
        y, fr = sol.y[:2, -1], sol.y[2, -1] / TWO_PI
        if prev is not None and abs(fr - prev) < 1e-11:
            return fr
        prev = fr
    raise AssertionError("no periodic state in 400 cycles")


@pytest.mark.parametrize(
    ("lam", "xi"), [(0.3, 1.0), (1.0, 0.1), (3.0, 0.5), (10.0, 0.05), (30.0, 0.2)]
)
def test_dahl_matches_brute_force_time_marching(lam, xi):
    reference = brute_force_2d(lam, xi)
    fr = float(transverse(dahl(lam), xi).friction_ratio)
    # The phase grid's error is second order in the step: at 256 steps per half period
    # 2e-8 to 5.1e-6 at these points (the largest at Lambda 30), at 1024 steps 16x
    # smaller; LSODA at rtol 1e-11 is far below both.
    assert abs(fr - reference) < 1e-5
    fine = float(transverse(dahl(lam), xi, n_phase=1024).friction_ratio)
    assert abs(fine - reference) < 1e-6
    assert abs(fine - reference) < abs(fr - reference) / 8 or abs(fr - reference) < 1e-7


def test_lugre_with_stribeck_and_damping_matches_brute_force():
    lam, xi, fs, vs, s1, s2 = 5.0, 0.3, 1.5, 0.5, 0.2, 0.05
    law = idtool.LuGre(fc_n=1.0, kt_n_m=lam, fs_n=fs, vs_m_s=vs, s1_n_s_m=s1, s2_n_s_m=s2)
    mean_force = brute_force_2d(lam, xi, fs, vs, s1, s2)
    c = transverse(law, xi, n_phase=1024)
    assert float(c.mean_friction_n) == pytest.approx(mean_force, abs=1e-6)


def test_phase_steps_converge_at_second_order():
    fr = [float(transverse(dahl(10.0), 0.1, n_phase=n).friction_ratio) for n in (64, 128, 256)]
    ref = float(transverse(dahl(10.0), 0.1, n_phase=4096).friction_ratio)
    ratios = [(fr[0] - ref) / (fr[1] - ref), (fr[1] - ref) / (fr[2] - ref)]
    assert ratios == pytest.approx([4.0, 4.0], rel=0.1)


def test_energy_balance_of_the_transverse_kernel():
    # Dahl stores no energy over a period: the friction power <F . V> is the pull's
    # power <F_x> v plus the vibration's <F_y V_y>, whose fundamental is the harmonic
    # Fc1 (V_y = a w cos theta): <F_y V_y> = a w Fc1 / 2
    xi = 0.3
    c = transverse(dahl(5.0), xi, n_phase=1024)
    vibration = 0.5 * float(c.harmonic_cos_n)
    assert float(c.mean_power_w) == pytest.approx(
        float(c.mean_friction_n) * xi + vibration, rel=1e-9
    )


# ------------------------------------------------------------------ normal
# FR under normal oscillation and its mean indentation, compiled once: called eagerly,
# each call traced and compiled its bisections' loops afresh (about 0.1 s a call, some
# thirty calls here). The values are the eager ones to round-off (at most 3.3e-16 apart
# at the points below), far inside every tolerance; the test against the direction's own
# (eager) cycle average keeps the eager function.
_normal_fr = jax.jit(idtool.normal_friction_ratio)
_indentation = jax.jit(_mean_indentation)


def return_map(beta, vt, n=20_000, cycles=3):
    """Time stepping of the elastic-perfectly plastic tangential spring under the
    normal force n(theta) (f <- clip(f + g dtheta, -n, n)): first order in the step."""
    c = float(_indentation(jnp.asarray(beta)))
    theta = (np.arange(n) + 0.5) * TWO_PI / n
    normal = beta * np.maximum(c + np.cos(theta), 0.0)
    step = vt * beta * TWO_PI / n
    f, out = normal[0], np.empty(n)
    for _ in range(cycles):
        for i in range(n):
            f = min(max(f + step, -normal[i]), normal[i])
            out[i] = f
    return out.mean(), normal.mean()


@pytest.mark.parametrize(("beta", "vt"), [(0.5, 0.3), (1.0, 0.5), (2.0, 0.2), (5.0, 0.1)])
def test_normal_matches_time_stepping(beta, vt):
    fr = float(_normal_fr(beta, vt))
    coarse, mean_n = return_map(beta, vt, 10_000)
    fine, _ = return_map(beta, vt, 160_000)
    assert mean_n == pytest.approx(1.0, abs=1e-7)  # <N> = N0 (eq. N2)
    # The stepping converges to eq. N3 at first order (with a ripple where the contact
    # returns between grid points, beta > 1): measured 2e-6 to 3e-6 off at 160 000
    # steps, 6e-5 to 8e-5 at 10 000 for beta >= 2 (below 1e-7 at both without contact loss)
    assert abs(fine - fr) < 5e-6
    assert abs(fine - fr) < abs(coarse - fr) / 8 or abs(coarse - fr) < 1e-7


def test_normal_limits():
    nfr = lambda b, v: float(_normal_fr(b, v))  # noqa: E731
    # no loss of contact: FR = 1 - beta h(vt), linear in the amplitude, FR -> 1 as a -> 0
    for vt in (0.1, 0.4, 0.8):
        h = (1.0 - nfr(0.5, vt)) / 0.5
        assert h > 0.0
        assert (1.0 - nfr(0.1, vt)) / 0.1 == pytest.approx(h, rel=1e-12)
        assert (1.0 - nfr(1e-6, vt)) / 1e-6 == pytest.approx(h, rel=1e-7)
    # vanishing tangential stiffness: the spring holds the lowest Amontons force
    assert nfr(0.3, 0.0) == pytest.approx(0.7, abs=1e-12)
    assert nfr(3.0, 0.0) == pytest.approx(0.0, abs=1e-12)  # contact lost each period
    # fast sliding: the stuck force outgrows the normal force's rise, never sticks
    assert nfr(0.5, 1.0) == 1.0 and nfr(4.0, 1.5) == 1.0
    # mean indentation under contact loss (eq. N2): <max(c + cos, 0)> = 1 / beta
    t = np.linspace(0.0, TWO_PI, 400_001)
    for beta in (1.5, 4.0):
        c = float(_indentation(jnp.asarray(beta)))
        assert np.trapezoid(np.maximum(c + np.cos(t), 0.0), t) / TWO_PI == pytest.approx(
            1.0 / beta, abs=1e-9
        )


def test_normal_direction_from_the_law():
    normal = idtool.DIRECTIONS.get("normal")
    v, w, n0, mu = 0.025, TWO_PI * 20e3, 450.0, 0.3
    # rigid Amontons friction: a normal oscillation at constant mean load changes nothing
    rigid = normal.cycle_average(idtool.Coulomb(fc_n=mu * n0), v, 2e-6, w, n0)
    assert float(rigid.friction_ratio) == 1.0
    law = idtool.Dahl(fc_n=mu * n0, kt_n_m=1e8)
    assert float(normal.cycle_average(law, v, 0.0, w, n0).friction_ratio) == 1.0
    a = 2e-6
    c = normal.cycle_average(law, v, a, w, n0)
    beta = 1e8 * a / (KAPPA * n0)
    vt = KAPPA * (v / (a * w)) / mu
    expected = float(idtool.normal_friction_ratio(beta, vt))
    assert float(c.friction_ratio) == pytest.approx(expected, abs=1e-15)
    assert 0.0 < float(c.friction_ratio) < 1.0


# ------------------------------------------------------------------ jit and gradients
def _central(fn, x, h):
    return (fn(x * (1 + h)) - fn(x * (1 - h))) / (2 * x * h)


@pytest.mark.parametrize("direction", ["transverse", "normal"])
def test_gradients_are_finite_and_match_central_differences(direction):
    cls = idtool.DIRECTIONS.get(direction)
    v, w, n0 = 0.025, TWO_PI * 20e3, 450.0

    def fr(kt, a, lugre=False):
        fc = 0.3 * n0
        law = (
            idtool.LuGre(fc_n=fc, kt_n_m=kt, fs_n=1.3 * fc, vs_m_s=0.05)
            if lugre
            else idtool.Dahl(fc_n=fc, kt_n_m=kt)
        )
        return cls.cycle_average(law, v, a, w, n0).friction_ratio

    def check(f, grad, kt, a, lugre):
        g = grad(kt, a)
        assert all(np.isfinite(float(x)) for x in g)
        assert float(f(kt, a)) == pytest.approx(float(fr(kt, a, lugre)), abs=1e-14)
        fd_kt = _central(lambda k: float(f(k, a)), kt, 1e-5)
        fd_a = _central(lambda x: float(f(kt, x)), a, 1e-5)
        assert float(g[0]) == pytest.approx(fd_kt, rel=1e-4, abs=1e-14)
        assert float(g[1]) == pytest.approx(fd_a, rel=1e-4, abs=1e-6)

    for lugre in (False, True):
        f = jax.jit(lambda k, x, lg=lugre: fr(k, x, lg))
        grad = jax.jit(jax.grad(f, argnums=(0, 1)))  # compiled once for both points
        for kt, a in ((1e8, 1e-6), (3e8, 3e-6)):
            check(f, grad, kt, a, lugre)


# ------------------------------------------------------------------ the default
def test_default_along_is_what_it_was():
    # values of on_friction_ratio at commit 29d241e (main, before the direction choice)
    c = PowerLimitedCoupling(gain=0.02, power_load_n=800.0)
    laws = [
        idtool.Dahl(fc_n=0.3 * 450.0, kt_n_m=2e8),
        idtool.LuGre(fc_n=0.3 * 670.0, kt_n_m=5e7, fs_n=0.36 * 670, vs_m_s=0.01),
        idtool.Coulomb(fc_n=0.25 * 270),
    ]
    points = [(450.0, 0.5, 0.025), (670.0, 0.7, 0.025), (270.0, 0.5, 0.05)]
    before = ["0x1.1a90da371dea6p-2", "0x1.2c2292e7f1bddp-2", "0x1.4275ae55fbcbep-2"]
    along = idtool.DIRECTIONS.get("along")
    for law, (n, alpha, speed), hexed in zip(laws, points, before, strict=True):
        fr = float(on_friction_ratio(law, c, n, alpha, speed, 20e3, 85e-6))
        # recorded on one CPU: XLA's elementary functions (its own vectorised
        # approximations, a few ulps each) give other last bits on another (an AMD EPYC:
        # 1 ulp on Dahl's, 5 on Coulomb's). Within 1e-14 relative (~45 ulps: the chain's
        # dozen functions, each a few ulps); a changed term or constant moves it by far more
        assert fr == pytest.approx(float.fromhex(hexed), rel=1e-14, abs=0)
        # and the explicit default is the implicit one, bit for bit on this machine
        chosen = on_friction_ratio(law, c, n, alpha, speed, 20e3, 85e-6, along)
        assert float(chosen).hex() == fr.hex()
    assert ModelSpec("dahl", "constant", "ar1", "slope", "constant", "steady").direction == (
        "along"
    )


# ------------------------------------------------------------------ recovery
def test_transverse_recovers_kt_from_friction_ratios():
    """Friction ratios simulated with the transverse Dahl contact at a known Kt (noise
    0.003 in FR) at 3 loads x 4 amplitudes; least squares on log Kt (mu known: FR
    depends on Kt / mu only) brings Kt back inside its 95% Gauss-Newton interval."""
    mu, kt_true, v, w, sd = 0.3, 2e8, 0.025, TWO_PI * 20e3, 0.003
    loads = np.repeat([270.0, 450.0, 670.0], 4)
    amps = np.tile([0.3e-6, 0.6e-6, 1.0e-6, 1.5e-6], 3)

    @jax.jit
    def frs(log_kt):
        def one(n, a):
            law = idtool.Dahl(fc_n=mu * n, kt_n_m=jnp.exp(log_kt))
            return idtool.transverse_cycle_average(law, v, a, w).friction_ratio

        return jax.vmap(one)(jnp.asarray(loads), jnp.asarray(amps))

    observed = np.asarray(frs(np.log(kt_true))) + sd * np.random.default_rng(7).standard_normal(
        loads.size
    )
    assert observed.min() > 0.1 and observed.max() < 0.95  # informative: well below 1
    jac = jax.jacfwd(frs)
    fit = least_squares(
        lambda p: np.asarray(frs(p[0])) - observed,
        x0=[np.log(1e7)],
        jac=lambda p: np.asarray(jac(p[0]))[:, None],
        xtol=1e-12,
    )
    log_kt = fit.x[0]
    dof = loads.size - 1
    s2 = float(fit.fun @ fit.fun) / dof
    j = np.asarray(jac(log_kt))
    se = np.sqrt(s2 / float(j @ j))
    assert abs(log_kt - np.log(kt_true)) < 1.96 * se
    assert se < 0.05  # Kt to about 5%


# ------------------------------------------------------------------ the fit's choice
def test_direction_is_a_registered_choice():
    assert idtool.DIRECTIONS.names() == ("along", "normal", "transverse")
    with pytest.raises(IdtoolError, match="unknown direction of vibration 'sideways'"):
        idtool.DIRECTIONS.get("sideways")


def test_sdof_is_refused_with_another_direction(small_fit_data):
    with pytest.raises(IdtoolError, match="with direction 'transverse'"):
        idtool.bench_model(small_fit_data, "dahl", "sdof", direction="transverse")
    model = idtool.bench_model(small_fit_data, "dahl", "sdof")
    assert model.direction.name == "along"


@pytest.fixture(scope="module")
def small_fit_data():
    from idtool._data._blocks import FIT_PERIODS_PER_BLOCK, prepare_fit_data

    dataset = idtool.load_dataset(idtool.example_dataset_path())
    return prepare_fit_data(dataset, mains_hz=50.0, periods_per_block=FIT_PERIODS_PER_BLOCK)


def test_fit_records_the_direction_and_reads_it_back(tmp_path):
    ds = idtool.load_dataset(idtool.example_dataset_path())
    fit = idtool.fit(
        ds,
        direction="transverse",
        actuator="slope",
        offset="constant",
        level="steady",
        starts=2,
        variability=False,
    )
    assert fit.artefact.chosen.model.direction.name == "transverse"
    assert "vibration transverse" in fit.report()
    fit.save(tmp_path / "fit", plots=False)
    doc = json.loads((tmp_path / "fit" / "fit.json").read_text())
    assert doc["direction"]["name"] == "transverse"
    assert list(schema_validator(FIT_JSON.schema).iter_errors(doc)) == []
    # a fit.json written before the choice (no direction) reads as along
    assert _spec({k: x for k, x in doc.items() if k != "direction"}, "constant").direction == (
        "along"
    )
    assert _spec(doc, "constant").direction == "transverse"
    assert _spec(doc, "constant", "dahl/constant/slope/constant").direction == "transverse"
    loaded = idtool.load_fit(tmp_path / "fit")
    model = loaded.artefact.chosen.model
    assert model.direction.name == "transverse"
    # the loaded model computes the same friction ratios as the fitted one
    v = model.values(jnp.asarray(fit.artefact.chosen.z))
    d = model.data
    np.testing.assert_array_equal(
        np.asarray(model.friction_ratios(v, d.op_load_n, d.op_alpha, d.op_speed_m_s)),
        np.asarray(
            fit.artefact.chosen.model.friction_ratios(v, d.op_load_n, d.op_alpha, d.op_speed_m_s)
        ),
    )


def test_the_stiffness_ratio_only_rescales_the_amplitude():
    # eq. N1: (beta, vt) depend on KAPPA and a through a / KAPPA only
    kt, a, v, w, n0, mu = 1e8, 2e-6, 0.025, TWO_PI * 20e3, 450.0, 0.3
    for s in (0.5, 2.0):
        beta = kt * a / (KAPPA * n0)
        vt = KAPPA * v / (a * w) / mu
        beta_s = kt * (s * a) / (s * KAPPA * n0)
        vt_s = s * KAPPA * v / (s * a * w) / mu
        assert float(_normal_fr(beta_s, vt_s)) == pytest.approx(
            float(_normal_fr(beta, vt)), abs=1e-15
        )
