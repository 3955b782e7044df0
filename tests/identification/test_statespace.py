"""The state-space kernels against statsmodels' Kalman filter, smoother and simulation smoother."""

from __future__ import annotations

import numpy as np
import pytest
from statsmodels.tsa.statespace.simulation_smoother import SimulationSmoother

from identification.estimation.statespace import (
    LinearGaussian,
    _cholesky,
    loglike,
    simulation_smoother,
    smooth,
)


def random_model(seed: int = 3, n: int = 60) -> LinearGaussian:
    """A time-varying model with a singular state covariance and missing observations."""
    rng = np.random.default_rng(seed)
    m, d = 3, 2
    transition = np.stack([np.eye(m) * 0.7 + 0.1 * rng.standard_normal((m, m)) for _ in range(n)])
    root = rng.standard_normal((m, m))
    state_cov = root @ root.T * 0.1
    state_cov[2, :] = state_cov[:, 2] = 0.0  # a state without its own noise, as φ
    y = rng.standard_normal((n, d))
    y[5, 0] = np.nan
    y[7] = np.nan
    return LinearGaussian(
        y=y,
        observed=np.array([0, 2]),
        obs_var=rng.uniform(0.1, 0.5, (n, d)),
        transition=transition,
        intercept=rng.standard_normal((n, m)),
        state_cov=state_cov,
        initial_mean=rng.standard_normal(m),
        initial_cov=np.diag([2.0, 1.0, 3.0]),
    )


def statsmodels_of(model: LinearGaussian) -> SimulationSmoother:
    d = model.y.shape[1]
    m = model.n_states
    ssm = SimulationSmoother(k_endog=d, k_states=m, k_posdef=m)
    ssm.bind(model.y)
    design = np.zeros((d, m))
    design[np.arange(d), model.observed] = 1.0
    ssm["design"] = design
    ssm["obs_cov"] = np.stack([np.diag(h) for h in model.obs_var], axis=-1)
    ssm["transition"] = np.moveaxis(model.transition, 0, -1)
    ssm["state_intercept"] = model.intercept.T
    ssm["selection"] = np.eye(m)
    ssm["state_cov"] = model.state_cov
    ssm.initialize_known(model.initial_mean, model.initial_cov)
    return ssm


def test_likelihood_and_smoother_agree_with_statsmodels() -> None:
    model = random_model()
    reference = statsmodels_of(model).smooth()
    ours = smooth(model)
    assert loglike(model) == pytest.approx(reference.llf_obs.sum(), rel=1e-10)
    assert ours.loglike == pytest.approx(reference.llf_obs.sum(), rel=1e-10)
    np.testing.assert_allclose(ours.mean, reference.smoothed_state.T, rtol=0, atol=1e-8)
    cov = np.moveaxis(reference.smoothed_state_cov, -1, 0)
    np.testing.assert_allclose(ours.cov, cov, rtol=0, atol=1e-8)


def test_simulation_smoother_agrees_with_statsmodels_given_the_same_draws() -> None:
    model = random_model(seed=7)
    n, d = model.y.shape
    m = model.n_states
    rng = np.random.default_rng(0)
    eps, eta = rng.standard_normal((1, n, d)), rng.standard_normal((1, n, m))
    initial = rng.standard_normal((1, m))
    ours = simulation_smoother(model, smooth(model), draws=(eps, eta, initial))[0]
    sim = statsmodels_of(model).simulation_smoother()
    sim.simulate(
        measurement_disturbance_variates=eps[0] * np.sqrt(model.obs_var),
        state_disturbance_variates=eta[0] @ _cholesky(model.state_cov).T,
        initial_state_variates=initial[0],
        pretransformed_measurement_disturbance_variates=True,
        pretransformed_state_disturbance_variates=True,
        pretransformed_initial_state_variates=True,
    )
    np.testing.assert_allclose(ours, sim.simulated_state.T, rtol=0, atol=1e-8)


def test_simulation_smoother_draws_have_the_posterior_moments() -> None:
    model = random_model(seed=11, n=30)
    smoothed = smooth(model)
    draws = simulation_smoother(model, smoothed, np.random.default_rng(1), size=4000)
    sd = np.sqrt(np.einsum("kii->ki", smoothed.cov))
    # 4000 draws: the sample mean is within 4 standard errors of the posterior mean.
    assert np.all(np.abs(draws.mean(axis=0) - smoothed.mean) < 4 * sd / np.sqrt(4000) + 1e-12)
    np.testing.assert_allclose(draws.std(axis=0), sd, rtol=0.08, atol=1e-9)


def test_a_model_of_inconsistent_shapes_names_the_array() -> None:
    model = random_model()
    with pytest.raises(ValueError, match=r"LinearGaussian\.intercept: shape"):
        LinearGaussian(
            y=model.y,
            observed=model.observed,
            obs_var=model.obs_var,
            transition=model.transition,
            intercept=model.intercept[:-1],
            state_cov=model.state_cov,
            initial_mean=model.initial_mean,
            initial_cov=model.initial_cov,
        )
