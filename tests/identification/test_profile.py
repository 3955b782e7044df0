"""Profile-likelihood intervals (identification.estimation.likelihood.profile_interval)."""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any

import numpy as np
import pytest
from scipy import stats

from identification.estimation.likelihood import OUTSIDE, profile_interval
from identification.instruments.tunnel import TunnelSpec, run_tunnel
from identification.methods import Context, fit, ml
from identification.methods.ml import maximum_likelihood
from identification.methods.pipeline import IdentifyOptions
from identification.recordings.recording import Recording

Z95 = float(stats.norm.ppf(0.975))


def _regression() -> tuple[np.ndarray, np.ndarray, float]:
    rng = np.random.default_rng(4)
    x = np.linspace(-1.0, 1.0, 200)
    y = 0.3 + 2.0 * x + 0.5 * rng.standard_normal(x.size)
    return x, y, 0.5


def test_on_a_gaussian_likelihood_the_profile_is_the_hessians_interval() -> None:
    x, y, sigma = _regression()
    design = np.column_stack([np.ones_like(x), x])
    beta, *_ = np.linalg.lstsq(design, y, rcond=None)
    cov = sigma**2 * np.linalg.inv(design.T @ design)

    def f(b: np.ndarray) -> float:
        r = y - design @ b
        return float(r @ r) / (2 * sigma**2)

    for i in range(2):
        se = math.sqrt(cov[i, i])
        found = profile_interval(f, beta, i, step=se)
        assert found.determined
        assert found.low == pytest.approx(beta[i] - Z95 * se, abs=0.01 * se)
        assert found.high == pytest.approx(beta[i] + Z95 * se, abs=0.01 * se)
        assert found.gain < 1e-6


def test_a_parameter_the_data_do_not_bound_is_open_on_that_side() -> None:
    def flat_in_second(b: np.ndarray) -> float:
        return 0.5 * (b[0] - 1.0) ** 2

    found = profile_interval(flat_in_second, np.array([1.0, 0.0]), 1, step=0.1, max_doublings=6)
    assert (found.low_end, found.high_end) == ("open", "open")
    assert not found.determined


def test_a_range_that_ends_inside_the_level_closes_that_side() -> None:
    def f(b: np.ndarray) -> float:
        return 0.5 * (b[0] - 0.1) ** 2  # SE 1: the 95 % interval would reach -1.86

    found = profile_interval(f, np.array([0.1]), 0, step=1.0, limits=(0.0, math.inf))
    assert found.low_end == "range" and found.low == 0.0
    assert found.high_end == "likelihood"
    assert found.high == pytest.approx(0.1 + Z95, abs=0.01)


def test_two_parameters_only_whose_sum_is_told_are_each_open() -> None:
    def sum_only(b: np.ndarray) -> float:
        return 50.0 * (b[0] + b[1] - 1.0) ** 2

    found = profile_interval(sum_only, np.array([0.5, 0.5]), 0, step=0.1, max_doublings=6)
    assert (found.low_end, found.high_end) == ("open", "open")


def test_the_profile_is_not_symmetric_where_the_likelihood_is_not() -> None:
    # A Poisson count's rate: the profile interval is the likelihood-ratio one, skewed up.
    count = 4.0

    def f(b: np.ndarray) -> float:
        rate = b[0]
        return OUTSIDE if rate <= 0 else rate - count * math.log(rate)

    found = profile_interval(f, np.array([count]), 0, step=2.0, limits=(0.0, math.inf))
    assert found.determined
    assert count - found.low < found.high - count
    # The likelihood-ratio interval of a count of 4: λ − 4 − 4·ln(λ/4) = χ²₁(0.95)/2, its
    # ends found to 1 % of the step (0.02).
    for end in (found.low, found.high):
        assert end - count - count * math.log(end / count) == pytest.approx(1.9207, abs=0.05)
    assert found.low == pytest.approx(1.24, abs=0.03)
    assert found.high == pytest.approx(9.29, abs=0.03)


def test_ml_profile_intervals_agree_with_the_hessian_on_a_well_identified_run() -> None:
    rec = run_tunnel(
        TunnelSpec(
            seed=5, schedule="prbs", duration=40, lead=5, log_dt=0.02, gyro_noise=1.0,
            model="constant",
        )
    )  # fmt: skip
    auto = maximum_likelihood(rec, "constant")
    profile = maximum_likelihood(rec, "constant", options=IdentifyOptions(intervals="profile"))
    assert set(auto.intervals) == {"alpha", "theta_bar", "a_per_s"}
    for name, wald in auto.intervals.items():
        assert wald["method"] == "hessian"
        found = profile.intervals[name]
        assert found["method"] == "profile" and found["determined"]
        width, hessian_width = found["high"] - found["low"], wald["high"] - wald["low"]
        assert width == pytest.approx(hessian_width, rel=0.15), name
        assert found["low"] < found["estimate"] < found["high"]


def test_the_models_edge_inside_the_level_closes_that_side_as_the_range() -> None:
    def f(b: np.ndarray) -> float:  # no model below -0.5 (an unstable rocket, say)
        return OUTSIDE if b[0] < -0.5 else 0.5 * b[0] ** 2

    found = profile_interval(f, np.array([0.0]), 0, step=1.0)
    assert found.low_end == "range"
    assert found.low == pytest.approx(-0.5, abs=1e-2)
    assert found.high_end == "likelihood"


def _two_basins(b: np.ndarray) -> float:
    """A likelihood with two optima 0.5 apart in log-likelihood: at 0 (the best) and at 6,
    each a unit-SE hill, the second parameter told at 1 either way."""
    return min(0.5 * b[0] ** 2, 0.5 * (b[0] - 6.0) ** 2 + 0.5) + 0.5 * (b[1] - 1.0) ** 2


def test_a_profile_from_each_basin_measured_from_the_best_joins_both() -> None:
    alone = profile_interval(_two_basins, np.array([0.0, 1.0]), 0, step=1.0)
    assert alone.high == pytest.approx(Z95, abs=0.01)  # blind to the second basin
    other = profile_interval(_two_basins, np.array([6.0, 1.0]), 0, step=1.0, reference=0.0)
    # Its level is the best's: 1.92 − 0.5 above its own optimum, not 1.92.
    half = math.sqrt(2.0 * (0.5 * stats.chi2.ppf(0.95, 1) - 0.5))
    assert other.low == pytest.approx(6.0 - half, abs=0.01)
    assert other.high == pytest.approx(6.0 + half, abs=0.01)
    joined = alone.joined([other])
    assert (joined.low, joined.high) == (alone.low, other.high)
    assert joined.estimate == 0.0 and joined.determined
    assert joined.evaluations == alone.evaluations + other.evaluations


#: benchmarks/closed_loop_identification.py's loop-only log 4: a rate loop with nothing on
#: top, reading the gyro 20 ms (half a sample) before each command.
HALF_SAMPLE_LOOP: dict[str, Any] = {"alpha": 1.4434241117895774, "beta": -2.9656234047409162,
                                    "beta_bar": 2.8843145098421408}  # fmt: skip
HALF_SAMPLE_GAIN = 0.9612495297573481


@functools.cache
def _half_sample_loop(delay: float = 0.02) -> Recording:
    rec = run_tunnel(
        TunnelSpec(
            seed=4, schedule="none", lead=2.0, duration=40.0, model="constant",
            **HALF_SAMPLE_LOOP, loop_gain=HALF_SAMPLE_GAIN, loop_delay=delay, stops=15.0,
            turbulence_sd=7.724098628345878, log_dt=0.04, gyro_noise=1.0, measured_fin=True,
        )
    )  # fmt: skip
    return dataclasses.replace(rec, fin_deg=None)  # the flight computer logs its command


def test_ml_profiles_every_basin_of_a_loop_alone_and_covers_the_rocket(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A rate loop with nothing on top: the fin doing nothing (α ≈ 0, the turbulence doing
    # all) is an optimum within the 95 % level of the rocket's; each basin is profiled.
    # (The profile from the fit's basin alone missed the truth.)  The log's loop answers
    # within a sample, where ml reports the rocket undetermined instead: that is set aside
    # here to reach the basins.
    monkeypatch.setattr(ml._Search, "loop_alone", None)
    truth = HALF_SAMPLE_LOOP
    found = maximum_likelihood(_half_sample_loop(), "constant")
    alpha = found.intervals["alpha"]
    assert alpha["method"] == "profile"  # not the Hessian's: the likelihood is not one hill
    assert len(alpha["optima"]) >= 2
    assert all(alpha["low"] <= v <= alpha["high"] for v in alpha["optima"])
    assert alpha["low"] <= truth["alpha"] <= alpha["high"]
    a = found.intervals["a_per_s"]
    assert a["low"] <= truth["beta_bar"] <= a["high"]


def test_ml_on_a_loop_alone_within_a_sample_says_the_rocket_is_not_determined() -> None:
    # Half a sample late, the fin answers the turbulence of the sample it is logged with:
    # ml is not consistent, and the rocket's gain, damping and asymmetry are not told
    # apart.
    found = fit(Context(_half_sample_loop()), "ml", ["constant"])["constant"]
    metrics = found.metrics
    intervals = metrics["intervals"]
    assert {i["method"] for i in intervals.values()} == {"loop"}
    assert not any(i["determined"] for i in intervals.values())
    assert intervals["alpha"]["low"] == pytest.approx(-1.0 / HALF_SAMPLE_GAIN)
    assert intervals["alpha"]["high"] == math.inf
    assert (intervals["a_per_s"]["low"], intervals["theta_bar"]["low"]) == (0.0, -90.0)
    assert all(math.isnan(se) for se in metrics["std_errors"].values())
    loop = metrics["loop_alone"]
    assert loop == {"gain": HALF_SAMPLE_GAIN, "delay_s": 0.02, "stated": True}
    adequacy = metrics["adequacy"]
    assert adequacy["verdict"] == "unreliable"
    (reason,) = [r for r in adequacy["reasons"] if "answers within the log's sample" in r]
    assert "dither" in reason and "--method instrumental" in reason
    assert not any("standard error" in r for r in adequacy["reasons"])


def test_ml_on_the_same_loop_a_sample_and_a_half_late_finds_the_rocket() -> None:
    # The loop's delay, not the loop, is what the rule reads: 60 ms at 25 Hz reads the rate
    # a sample before the interval the fin acts over.
    found = maximum_likelihood(_half_sample_loop(0.06), "constant")
    assert not found.loop_alone
    alpha = found.intervals["alpha"]
    assert alpha["determined"]
    assert alpha["low"] <= HALF_SAMPLE_LOOP["alpha"] <= alpha["high"]
