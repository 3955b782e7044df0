"""Maximum-likelihood identification (``method="ml"``) against known truths.

The truths differ from the paper's on purpose (gain, sign of θ̄, a(θ) shape,
schedule, turbulence distribution and correlation time, sensors): a method
that only finds the paper's rocket is a defect.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from identification.compiled import interval_maps
from identification.estimation.likelihood import numerical_hessian
from identification.estimation.statespace import loglike
from identification.instruments.tunnel import TunnelSpec, run_tunnel, spec_from_command
from identification.methods import fit
from identification.methods.ml import maximum_likelihood, posterior_given
from identification.methods.pipeline import IdentifyOptions, identify, measurements
from identification.methods.rollspace import prepare, roll_loglike, roll_parts, roll_system
from identification.model import RollParams, simulate
from identification.recordings.recording import Recording

NEGATIVE_ASYMMETRY = TunnelSpec(seed=3, alpha=0.9, beta=-3.0, correlation_time=0.3)
STAIRCASE_LAPLACE = TunnelSpec(
    seed=5,
    schedule="staircase",
    steps=12,
    turbulence="laplace",
    correlation_time=1.0,
    alpha_bar=0.02,
    beta_bar=1.0,
)


def ar1_turbulence(n: int, sd: float, lag_one: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    u = np.empty(n)
    u[0] = sd * rng.standard_normal()
    for k in range(1, n):
        u[k] = lag_one * u[k - 1] + sd * np.sqrt(1 - lag_one**2) * rng.standard_normal()
    return u


def doublet_recording(*, gyro: bool, encoder: bool, dt: float = 0.1) -> Recording:
    """Doublets, a ramp and random steps (no dwell long enough for the paper's steps)."""
    rng = np.random.default_rng(42)
    n = round(300 / dt)
    t = dt * np.arange(n + 1, dtype=float)
    command = np.zeros(n + 1)
    command[(t % 8 >= 1) & (t % 8 < 3)] = 15.0
    command[(t % 8 >= 3) & (t % 8 < 5)] = -15.0
    ramp = (t >= 100) & (t < 160)
    command[ramp] = -30 + (t[ramp] - 100)
    rand = t >= 200
    command[rand] = np.repeat(rng.uniform(-25, 25, n), round(1.5 / dt))[: int(rand.sum())]
    truth = RollParams(alpha=0.8, theta_bar_deg=-2.5, beta_bar_per_s=1.8, alpha_bar_per_deg_s=0.015)
    u_d = ar1_turbulence(n + 1, 8.0, np.exp(-dt / 0.5), seed=1)
    sim = simulate(truth, dt, command[:-1], u_d[:-1], substeps=max(1, round(dt / 0.01)))
    columns: dict[str, np.ndarray] = {}
    if encoder:
        columns["roll_deg"] = np.floor(sim.angle_deg / (360 / 1024) + 1e-9) * (360 / 1024)
    if gyro:
        eps = np.random.default_rng(2).standard_normal(n + 1)
        columns["roll_rate_dps"] = (1 + 0.02 * eps) * sim.rate_dps
    return Recording(
        name="doublets",
        source="synthetic",
        time_s=t,
        fin_cmd_deg=command,
        ud_true_deg=u_d,
        metadata={},
        **columns,
    )


def within(estimate: float, truth: float, se: float, k: float = 3.5) -> bool:
    return abs(estimate - truth) <= k * se


@pytest.fixture(scope="module")
def negative() -> tuple[Recording, object]:
    rec = run_tunnel(NEGATIVE_ASYMMETRY)
    return rec, maximum_likelihood(rec, "theta")


@pytest.mark.parametrize("sensors", ["encoder", "gyro and encoder"])
def test_the_roll_likelihood_is_the_general_kalman_filter(negative: tuple, sensors: str) -> None:
    rec = negative[0] if sensors == "encoder" else doublet_recording(gyro=True, encoder=True)
    data = prepare(measurements(rec, IdentifyOptions()))
    nat = {
        "alpha": 0.7,
        "theta_bar": 1.0,
        "alpha_bar": -0.01,
        "beta_bar": 2.0,
        "ar": np.array([0.6, 0.1]),
        "innovation_sd": 5.0,
        "gyro": 0.0 if sensors == "encoder" else 0.03,
    }
    parts = roll_parts(data, nat)
    assert parts is not None
    fast = roll_loglike(data, parts)  # the numba kernel with the roll model's sparse update
    assert np.all(np.isfinite(parts.obs_var))  # the gyro's variances filled in
    assert fast == pytest.approx(loglike(roll_system(data, parts)), rel=1e-12)


def test_the_gyro_variance_is_taken_at_the_predicted_rate() -> None:
    """Eq. 52's g²·v² at E[v²] before the reading, not at the reading: a reading's own
    noise must not set its weight."""
    rec = doublet_recording(gyro=True, encoder=False)
    data = prepare(measurements(rec, IdentifyOptions()))
    nat = {
        "alpha": 0.8,
        "theta_bar": -2.5,
        "alpha_bar": 0.015,
        "beta_bar": 1.8,
        "ar": np.array([0.8]),
        "innovation_sd": 5.0,
        "gyro": 0.02,
    }
    parts = roll_parts(data, nat)
    assert parts is not None
    roll_loglike(data, parts)
    # Two recordings that differ in one reading only: that reading's variance is the same.
    spiked = data.y.copy()
    spiked[500, 0] *= 1.5
    again = roll_parts(data, nat)
    assert again is not None
    roll_loglike(replace(data, y=spiked), again)
    assert again.obs_var[500, 0] == parts.obs_var[500, 0]
    assert again.obs_var[501, 0] != parts.obs_var[501, 0]  # later ones see it
    # Its size is g²·v² on average.
    rate = np.asarray(rec.roll_rate_dps)
    assert np.mean(parts.obs_var[:, 0]) == pytest.approx(0.02**2 * np.mean(rate**2), rel=0.05)


def test_the_interval_maps_are_the_models_simulation(negative: tuple) -> None:
    """The state-space transition is the one closed form, composed over the fine grid."""
    rec, _ = negative
    data = prepare(measurements(rec, IdentifyOptions()))
    p = RollParams(0.9, -3.3, 2.4, -0.029)
    u = ar1_turbulence(data.n - 1, 9.0, 0.8, seed=0)
    maps = interval_maps(p, data.theta_fine, data.per, data.h)
    v, phi = np.empty(data.n), np.empty(data.n)
    v[0], phi[0] = 3.0, 1.0
    for k, (e, g, f, a, b, c) in enumerate(maps):
        v[k + 1] = e * v[k] + g * u[k] + f
        phi[k + 1] = phi[k] + a * v[k] + b * u[k] + c
    sim = simulate(
        p,
        data.h,
        data.theta_fine,
        np.repeat(u, data.per),
        rate0_dps=3.0,
        angle0_deg=1.0,
        servo=None,
        substeps=1,
    )
    np.testing.assert_allclose(v, sim.rate_dps[:: data.per], rtol=0, atol=1e-9)
    np.testing.assert_allclose(phi, sim.angle_deg[:: data.per], rtol=0, atol=1e-7)


def check_recovery(rec: Recording, spec: TunnelSpec, found: object) -> None:
    truth = spec.params()
    p, se = found.params, found.std_errors  # type: ignore[attr-defined]
    assert within(p.alpha, truth.alpha, se["alpha"]), (p, se)
    assert within(p.theta_bar_deg, truth.theta_bar_deg, se["theta_bar"]), (p, se)
    assert within(p.alpha_bar_per_deg_s, truth.alpha_bar_per_deg_s, se["alpha_bar"]), (p, se)
    assert within(p.beta_bar_per_s, truth.beta_bar_per_s, se["beta_bar_per_s"]), (p, se)
    # Posterior of u_d: the truth lies in the 90 % band about 90 % of the time.
    ud = np.asarray(rec.ud_true_deg)[:-1]
    err = found.u_d_deg - ud  # type: ignore[attr-defined]
    coverage = float(np.mean(np.abs(err) <= 1.645 * found.u_d_sd_deg))  # type: ignore[attr-defined]
    assert 0.82 <= coverage <= 0.97, coverage


def test_recovers_a_gain_and_asymmetry_of_the_other_sign(negative: tuple) -> None:
    rec, found = negative
    check_recovery(rec, NEGATIVE_ASYMMETRY, found)


def test_recovers_rising_damping_from_a_staircase_with_laplace_turbulence() -> None:
    rec = run_tunnel(STAIRCASE_LAPLACE)
    check_recovery(rec, STAIRCASE_LAPLACE, maximum_likelihood(rec, "theta"))


def test_its_disturbance_is_closer_to_the_truth_than_the_papers(negative: tuple) -> None:
    rec, found = negative
    paper = identify(rec, IdentifyOptions(noise_runs=0)).disturbances["theta"].u_d_deg
    ud = np.asarray(rec.ud_true_deg)[:-1]
    ml_mae = float(np.mean(np.abs(found.u_d_deg - ud)))
    paper_mae = float(np.mean(np.abs(paper - ud[: paper.size])))
    assert ml_mae < 0.9 * paper_mae, (ml_mae, paper_mae)


def test_posterior_draws_are_turbulence_of_the_right_size_and_reproducible(
    negative: tuple,
) -> None:
    rec, found = negative
    draws = found.posterior_draws(20, seed=4)
    assert draws.shape == (20, rec.n_samples - 1)
    np.testing.assert_array_equal(draws, found.posterior_draws(20, seed=4))
    assert not np.array_equal(draws, found.posterior_draws(20, seed=5))
    true_sd = float(np.std(np.asarray(rec.ud_true_deg)))
    assert float(np.mean(draws.std(axis=1))) == pytest.approx(true_sd, rel=0.1)
    # Each draw is rougher than the posterior mean: it carries the fast part.
    assert float(np.mean(draws.std(axis=1))) > 1.1 * float(np.std(found.u_d_deg))


@pytest.mark.parametrize(
    ("gyro", "encoder", "dt"),
    [(True, False, 0.1), (False, True, 0.1), (True, True, 0.02)],
    ids=["rate-only", "angle-only", "both-50Hz"],
)
def test_works_on_doublets_ramps_and_random_inputs(gyro: bool, encoder: bool, dt: float) -> None:
    rec = doublet_recording(gyro=gyro, encoder=encoder, dt=dt)
    found = maximum_likelihood(rec, "theta")
    p, se = found.params, found.std_errors
    assert within(p.alpha, 0.8, se["alpha"]), (p, se)
    assert within(p.theta_bar_deg, -2.5, se["theta_bar"]), (p, se)
    assert within(p.alpha_bar_per_deg_s, 0.015, se["alpha_bar"]), (p, se)


def test_ml_is_a_registered_method_with_likelihood_metrics(negative: tuple) -> None:
    rec, _ = negative
    fits = fit(rec, "ml", ["constant", "theta"], IdentifyOptions(noise_runs=0))
    for model, found in fits.items():
        assert found.method == "ml" and found.model == model
        m = found.metrics
        assert m["aic"] == pytest.approx(2 * m["n_params"] - 2 * m["loglike"])
        assert m["ar_order"] >= 1 and m["converged"]
        # Started from its own posterior initial state, the replay follows the encoder.
        assert m["resim_angle_mae_deg"] < 0.2
    # θ-dependent damping is the truth here; the likelihood says so.
    assert fits["theta"].metrics["aic"] < fits["constant"].metrics["aic"]


def test_the_threaded_hessian_is_statsmodels_approx_hess3() -> None:
    """Same points, same arithmetic: the standard errors do not depend on the threads."""
    from statsmodels.tools.numdiff import approx_hess3

    def f(x: np.ndarray) -> float:
        return float(np.sum(np.sin(x) * x[::-1]) + x[0] ** 3 * x[2] + np.exp(0.1 * x[4]))

    x = np.array([0.3, -1.2, 2.0, 0.05, 7.0])
    assert np.array_equal(numerical_hessian(f, x), approx_hess3(x, f))


def _with_sensor_noise(rec: Recording, gyro_sd: float, angle_sd: float, seed: int) -> Recording:
    """``rec`` read by a MEMS gyro (additive white noise) and an analogue angle sensor."""
    rng = np.random.default_rng(seed)
    assert rec.roll_rate_dps is not None and rec.roll_deg is not None
    return replace(
        rec,
        roll_rate_dps=np.asarray(rec.roll_rate_dps) + gyro_sd * rng.standard_normal(rec.n_samples),
        roll_deg=np.asarray(rec.roll_deg) + angle_sd * rng.standard_normal(rec.n_samples),
    )


PRBS_100HZ = TunnelSpec(
    seed=7, schedule="prbs", log_dt=0.01, duration=60.0, lead=3.0, gyro_noise=1.0, beta=-1.5
)


def test_real_sensor_noise_is_estimated_and_not_carried_by_the_turbulence() -> None:
    """An analogue angle read as an exact encoder, and a gyro's white noise read as eq. 52's
    multiplicative noise, made the likelihood run to a unit-root turbulence and a singular
    stationary covariance (a public aircraft roll rig's recording: LinAlgError)."""
    clean = run_tunnel(PRBS_100HZ)
    truth = clean.truth()
    assert truth is not None
    found = maximum_likelihood(clean, "theta")
    assert found.gyro_floor_dps == 0.0 and found.angle_noise_deg == 0.0  # eq. 52 and an encoder
    noisy = maximum_likelihood(_with_sensor_noise(clean, 0.5, 0.3, seed=1), "theta")
    assert noisy.gyro_floor_dps == pytest.approx(0.5, rel=0.1)
    assert noisy.angle_noise_deg == pytest.approx(0.3, rel=0.1)
    for f in (found, noisy):
        assert abs(f.params.alpha - truth.alpha) < 3 * f.std_errors["alpha"]
        assert abs(f.params.theta_bar_deg - truth.theta_bar_deg) < 3 * f.std_errors["theta_bar"]


def test_a_chirp_is_fitted_from_the_one_step_regression() -> None:
    """The line through rate against fin reads a chirp as a tiny gain and a 30° asymmetry;
    from there the optimiser found a rocket the fin barely moves."""
    spec = TunnelSpec(
        seed=5, schedule="chirp", log_dt=0.005, duration=10.0, lead=2.0, chirp_to=5.0,
        substeps=2, gyro_noise=1.0,
    )  # fmt: skip
    rec = _with_sensor_noise(run_tunnel(spec), 0.5, 0.3, seed=2)
    truth = rec.truth()
    assert truth is not None
    f = maximum_likelihood(rec, "constant")
    assert abs(f.params.alpha - truth.alpha) < 3 * f.std_errors["alpha"]
    assert abs(f.params.theta_bar_deg - truth.theta_bar_deg) < 5.0


def test_a_recording_without_turbulence_keeps_the_fit_regular() -> None:
    """No turbulence: the AR turbulence runs to a unit root and a vanishing innovation,
    which the optimiser's box holds where the stationary covariance is regular."""
    rec = run_tunnel(TunnelSpec(seed=2, turbulence_sd=0.0, model="constant", gyro_noise=1.0))
    truth = rec.truth()
    assert truth is not None
    f = maximum_likelihood(rec, "constant")
    assert f.params.alpha == pytest.approx(truth.alpha, rel=1e-3)
    assert f.params.beta_bar_per_s == pytest.approx(truth.beta_bar_per_s, rel=1e-3)


def test_the_band_carries_the_parameters_uncertainty_on_a_short_record() -> None:
    """On 15-s doublets α is known to ~15 %: the smoother under the fitted parameters alone
    held the true u_d in its 90 % band about 60 % of the time; with the parameters'
    uncertainty added (delta method) the band widens and holds it about as often as it says."""
    inside, total = 0, 0
    for seed in range(4):
        spec = spec_from_command(
            f"--seed {seed} --log-dt 0.01 --gyro-noise 1 --schedule doublets --steps 4 "
            "--pulse 1 --dwell-min 1 --dwell-max 2 --lead 1"
        )
        rec = run_tunnel(spec)
        found = maximum_likelihood(rec, "theta")
        plug_in = posterior_given(
            rec, found.params, found.ar.tolist(), found.sd_deg, gyro_noise=found.gyro_noise
        )
        assert np.all(found.u_d_sd_deg >= plug_in.u_d_sd_deg - 1e-9)
        assert np.mean(found.u_d_sd_deg) > 1.2 * np.mean(plug_in.u_d_sd_deg)
        # the mean is kept (to the last bits only where numpy's loops round both smoothers'
        # sums alike: with AVX-512 they differ by ~1e-11°)
        np.testing.assert_allclose(found.u_d_deg, plug_in.u_d_deg, rtol=0, atol=1e-9)
        assert set(found.correlations) >= {"alpha~theta_bar", "alpha_bar~beta_bar_per_s"}
        assert all(-1.0 <= r <= 1.0 for r in found.correlations.values())
        assert rec.ud_true_deg is not None
        u = np.asarray(found.u_d_deg)
        inside += int(np.sum(np.abs(u - rec.ud_true_deg[: u.size]) <= 1.645 * found.u_d_sd_deg))
        total += u.size
    assert 0.8 < inside / total < 0.97


def test_innovations_are_white_under_the_fit_and_not_under_a_gain_30_percent_off() -> None:
    from identification.methods.adequacy import adequacy
    from identification.methods.ml import innovation_checks

    spec = spec_from_command(
        "--seed 0 --log-dt 0.01 --gyro-noise 1 --schedule doublets --steps 12 --pulse 1 "
        "--dwell-min 1 --dwell-max 3 --lead 2"
    )
    rec = run_tunnel(spec)
    found = maximum_likelihood(rec, "theta")
    right = innovation_checks(found)
    assert right["sensor"] == "gyro" and right["n"] == rec.n_samples
    assert right["max_acf"] < 0.04 and right["ljung_box_p"] > 0.01
    assert abs(right["skewness"]) < 0.2 and abs(right["excess_kurtosis"]) < 0.5
    off = replace(found.params, alpha=1.3 * found.params.alpha)
    given = posterior_given(rec, off, found.ar.tolist(), found.sd_deg, gyro_noise=found.gyro_noise)
    wrong = innovation_checks(given)
    assert wrong["max_acf"] > 0.05 and wrong["ljung_box_p"] < 1e-3
    judged = adequacy(measurements(rec, IdentifyOptions()), off, given.disturbance(),
                      {"innovations": wrong})  # fmt: skip
    assert any("innovations are not white" in r for r in judged.reasons)
