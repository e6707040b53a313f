"""The Levenberg-Marquardt solver with a coloured Jacobian (idtool._fit._lm), checked against
dense JAX Jacobians and SciPy's least_squares."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from sample_helpers import random_arrow
from scipy.optimize import least_squares

import idtool
from idtool._data._blocks import prepare_fit_data
from idtool._fit._arrow import Arrow, DenseNormal
from idtool._fit._lm import (
    ColouredJacobian,
    ColouredLevenbergMarquardt,
    arrow_equations,
    coloured_equations,
    levenberg_marquardt,
    levenberg_marquardt_loop,
    normal_equations,
)
from idtool._fit._program import bench_normal_equations, level_structure
from idtool._model._benchmodel import bench_model

# Three groups of decays sharing a rate k; each group has its own amplitude and offset.
TIMES = np.linspace(0.0, 3.0, 40)
GROUPS = 3


def decay_problem(seed: int = 0):
    rng = np.random.default_rng(seed)
    amp, off, k = np.array([1.0, 2.0, 0.5]), np.array([0.1, -0.2, 0.3]), 1.3
    y = amp[:, None] * np.exp(-k * TIMES) + off[:, None]
    y = (y + 0.01 * rng.standard_normal(y.shape)).ravel()
    row_group = np.repeat(np.arange(GROUPS), TIMES.size)
    # z = [log k, amp_0..2, off_0..2]
    param_group = np.array([-1, 0, 1, 2, 0, 1, 2])

    def residuals(z, scale=1.0):
        model = z[1:4, None] * jnp.exp(-jnp.exp(z[0]) * TIMES) + z[4:7, None]
        return scale * (model.ravel() - y)

    return residuals, ColouredJacobian.from_groups(param_group, row_group)


def test_colouring_uses_one_tangent_per_shared_parameter_and_per_group_slot():
    _, structure = decay_problem()
    assert structure.seeds.shape == (3, 7)  # k; amplitudes; offsets
    np.testing.assert_array_equal(structure.colour, [0, 1, 1, 1, 2, 2, 2])


def test_normal_equations_equal_the_dense_jacobians_on_a_toy_problem():
    fn, structure = decay_problem()
    z = jnp.array([0.1, 0.9, 1.8, 0.6, 0.0, 0.1, 0.2])
    r, jtj, jtr = normal_equations(fn, z, structure)
    jac = jax.jacfwd(fn)(z)
    np.testing.assert_allclose(r, fn(z), rtol=0, atol=0)
    np.testing.assert_allclose(jtj, jac.T @ jac, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(jtr, jac.T @ fn(z), rtol=1e-12, atol=1e-12)


def test_arrowhead_blocks_equal_the_dense_normal_equations_on_a_toy_problem():
    fn, structure = decay_problem()
    z = jnp.array([0.1, 0.9, 1.8, 0.6, 0.0, 0.1, 0.2])
    r, arrow = arrow_equations(fn, z, structure)
    np.testing.assert_array_equal(r, fn(z))
    _, jtj, jtr = normal_equations(fn, z, structure)
    assert arrow.d.shape == (GROUPS, 2, 2) and arrow.a.shape == (1, 1)
    dense_jtj, dense_jtr = arrow.dense()
    np.testing.assert_allclose(dense_jtj, jtj, rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(dense_jtr, jtr, rtol=1e-14, atol=1e-14)


def jax_arrow(seed: int) -> Arrow:
    """:func:`sample_helpers.random_arrow` (12 rows a trace) on JAX arrays."""
    return jax.tree.map(jnp.asarray, random_arrow(seed))


@pytest.mark.parametrize("masked", [False, True])
def test_schur_solve_equals_the_dense_solve(masked):
    """The arrowhead's solve (nuisances eliminated, Schur complement, back-substitution),
    product, diagonal and masking are the dense matrix's."""
    arrow = jax_arrow(0)
    p = arrow.grad.size
    rng = np.random.default_rng(1)
    mask = jnp.asarray(rng.random(p) > 0.3) if masked else jnp.ones(p, bool)
    arrow = arrow.masked(mask)
    dense = DenseNormal(*jax_arrow(0).dense()).masked(mask)
    np.testing.assert_array_equal(arrow.dense()[0], dense.jtj)
    np.testing.assert_array_equal(arrow.grad, dense.grad)
    shift, v = jnp.asarray(rng.random(p)), jnp.asarray(rng.standard_normal(p))
    x = arrow.solve(shift, v)
    np.testing.assert_allclose(x, dense.solve(shift, v), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(arrow.matvec(x), dense.matvec(x), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(arrow.diagonal(), np.diag(dense.jtj), rtol=0, atol=0)
    if masked:  # frozen parameters: identity rows, decoupled from the rest
        off = ~np.asarray(mask)
        np.testing.assert_allclose(np.asarray(x)[off], (v / (1.0 + shift))[off], rtol=1e-15)


def test_normal_equations_equal_the_dense_jacobians_for_the_bench_model():
    """The fit's whitened residuals mix neighbouring blocks, but never across traces,
    so the colouring stays exact (rel 1e-10: only summation order differs)."""
    data = prepare_fit_data(idtool.load_dataset(idtool.example_dataset_path()), periods_per_block=2)
    model = bench_model(data, "dahl", "power-limited")
    rng = np.random.default_rng(1)
    z = jnp.asarray(model.z0() + 0.3 * rng.standard_normal(len(model.names)))

    def fn(zz):
        return model.residuals(zz, 0.5)

    structure = ColouredJacobian.from_groups(model.param_group, data.block_trace)
    _, jtj, jtr = jax.jit(lambda zz: normal_equations(fn, zz, structure))(z)
    jac = jax.jit(jax.jacfwd(fn))(z)
    scale = np.sqrt(np.outer(np.diag(jac.T @ jac), np.diag(jac.T @ jac)))
    assert np.max(np.abs(jtj - jac.T @ jac) / scale) < 1e-10
    np.testing.assert_allclose(jtr, jac.T @ fn(z), rtol=1e-9, atol=1e-9 * np.max(np.abs(jtr)))
    assert structure.seeds.shape[0] == model.n_shared + 4  # 10, not 102
    # What the fit uses: the chain rule through the per-trace levels (8 JVPs).
    levels_structure = level_structure(model)
    r2, normal, (levels, dlevels, *_) = jax.jit(
        lambda m, zz: bench_normal_equations(m, levels_structure, zz, 0.5)
    )(model, z)
    assert isinstance(normal, Arrow)  # blocks, not the dense matrix
    jtj2, jtr2 = normal.dense()
    np.testing.assert_allclose(r2, fn(z), rtol=1e-12, atol=1e-10)
    assert np.max(np.abs(jtj2 - jac.T @ jac) / scale) < 1e-9
    np.testing.assert_allclose(jtr2, jac.T @ fn(z), rtol=1e-8, atol=1e-9 * np.max(np.abs(jtr)))
    assert levels_structure.seeds.shape[0] == 8
    # ... and the levels it hands the delta method, with their derivatives.
    k, m = len(model.physical_names), data.n_traces
    off, on, _ = model.levels(model.values(z))
    np.testing.assert_allclose(levels, np.concatenate([off, on]), rtol=1e-14)

    def lv(zp):
        off, on, _ = model.levels(model.values(z.at[:k].set(zp)))
        return jnp.concatenate([off, on])

    h = 1e-6
    fd = np.stack(
        [(lv(z[:k].at[j].add(h)) - lv(z[:k].at[j].add(-h))) / (2 * h) for j in range(k)], 1
    )
    np.testing.assert_allclose(dlevels, fd, rtol=1e-6, atol=1e-7 * np.max(np.abs(fd)))
    assert dlevels.shape == (2 * m, k)


def test_lm_matches_scipy_least_squares():
    fn, structure = decay_problem()
    z0 = np.array([0.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    out = jax.jit(levenberg_marquardt, static_argnums=0)(
        coloured_equations(fn, structure), jnp.asarray(z0), 1.0, jnp.ones(7, bool), 100
    )
    ref = least_squares(lambda z: np.asarray(fn(jnp.asarray(z))), z0, xtol=1e-15, ftol=1e-15)
    assert bool(out.converged)
    # Agreement in standard errors: the stopping rule promises sqrt(1e-8) = 1e-4.
    jac = np.asarray(jax.jacfwd(fn)(jnp.asarray(ref.x)))
    sigma2 = 2 * ref.cost / (jac.shape[0] - jac.shape[1])
    se = np.sqrt(np.diag(sigma2 * np.linalg.inv(jac.T @ jac)))
    assert np.max(np.abs(np.asarray(out.z) - ref.x) / se) < 1e-3
    assert float(out.loss) == pytest.approx(ref.cost, rel=1e-10)
    # The returned normal equations are those at the solution.
    np.testing.assert_allclose(out.jtj, jac.T @ jac, rtol=1e-6)


def test_masked_parameters_stay_put_and_the_rest_is_optimal_given_them():
    fn, structure = decay_problem()
    z0 = jnp.array([0.5, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    mask = jnp.array([False, True, True, True, True, True, True])
    out = levenberg_marquardt(coloured_equations(fn, structure), z0, 1.0, mask, 100)
    assert float(out.z[0]) == 0.5
    # With k fixed the model is linear in the rest: compare with the linear solve.
    basis = np.exp(-np.exp(0.5) * TIMES)
    y = -np.asarray(fn(jnp.zeros(7)))  # the data (the model is zero at z = 0)
    for g in range(GROUPS):
        a = np.column_stack([basis, np.ones_like(basis)])
        coef = np.linalg.lstsq(a, y[g * TIMES.size : (g + 1) * TIMES.size], rcond=None)[0]
        np.testing.assert_allclose(np.asarray(out.z)[[1 + g, 4 + g]], coef, rtol=1e-6, atol=1e-8)


def test_max_steps_stops_the_loop_and_says_not_converged():
    fn, structure = decay_problem()
    z0 = jnp.array([2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    out = levenberg_marquardt(coloured_equations(fn, structure), z0, 1.0, jnp.ones(7, bool), 2)
    assert int(out.steps) == 2
    assert not bool(out.converged)


def test_lm_matches_optimistix_levenberg_marquardt():
    """Same optimum as optimistix's own LevenbergMarquardt (dense Jacobians, QR), which
    the coloured solver replaces in the fit."""
    import optimistix as optx

    fn, structure = decay_problem(seed=3)
    z0 = jnp.array([0.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    ours = levenberg_marquardt(coloured_equations(fn, structure), z0, 1.0, jnp.ones(7, bool), 100)
    ref = optx.least_squares(
        lambda z, _: fn(z), optx.LevenbergMarquardt(rtol=1e-12, atol=1e-12), z0, max_steps=200
    )
    np.testing.assert_allclose(ours.z, ref.value, rtol=1e-5, atol=1e-7)


def test_the_fit_runs_through_optimistix(monkeypatch):
    """levenberg_marquardt is optimistix.least_squares with the coloured solver."""
    import optimistix as optx

    calls = []
    real = optx.least_squares

    def spy(fn, solver, *args, **kw):
        calls.append(solver)
        return real(fn, solver, *args, **kw)

    monkeypatch.setattr(optx, "least_squares", spy)
    fn, structure = decay_problem()
    z0 = jnp.array([0.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    out = levenberg_marquardt(coloured_equations(fn, structure), z0, 1.0, jnp.ones(7, bool), 100)
    assert bool(out.converged)
    assert len(calls) == 1 and isinstance(calls[0], ColouredLevenbergMarquardt)


@pytest.fixture(scope="module")
def example_lm_programs():
    """The example's model and the two drivers, each one jitted program with the step
    budget traced (levenberg_marquardt's ``max_steps`` is a traced option): both budgets
    below run the same two programs (each budget baked in compiled them twice, 2 x 7 s)."""
    data = prepare_fit_data(idtool.load_dataset(idtool.example_dataset_path()), periods_per_block=2)
    model = bench_model(data, "dahl", "power-limited")
    z0 = jnp.asarray(model.z0())
    mask = jnp.ones(z0.size, bool)
    structure = level_structure(model)

    def run(m, z, max_steps, drv):
        equations = jax.tree_util.Partial(bench_normal_equations, m, structure)
        return drv(equations, z, 0.2, mask, max_steps)

    programs = [
        jax.jit(lambda m, z, n, drv=drv: run(m, z, n, drv))
        for drv in (levenberg_marquardt, levenberg_marquardt_loop)
    ]
    return model, z0, programs


@pytest.mark.parametrize("max_steps", [3, 100])
def test_optimistix_solver_takes_the_reference_loops_iterates(max_steps, example_lm_programs):
    """The optimistix-driven solver and the plain while-loop (the reference the fit
    benchmark times it against) run the same update: same steps, linearisations and
    end point, to rounding (the closure-converted residual function may fuse
    differently: 1e-12 on the internal scale, where standard errors are ~1e-2)."""
    model, z0, programs = example_lm_programs
    outs = [program(model, z0, jnp.asarray(max_steps)) for program in programs]
    ours, ref = outs
    assert int(ours.steps) == int(ref.steps) and int(ours.n_jacobians) == int(ref.n_jacobians)
    assert bool(ours.converged) == bool(ref.converged) == (max_steps == 100)
    np.testing.assert_allclose(ours.z, ref.z, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ours.loss, ref.loss, rtol=1e-12)
    np.testing.assert_allclose(ours.jtj, ref.jtj, rtol=1e-10, atol=1e-10 * float(jnp.max(ref.jtj)))
