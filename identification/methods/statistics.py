"""Statistics of the identified disturbance (paper §3.4, Fig. 18).

For each trace (``u_d,θ`` and ``u_d,constant``): the normalised histogram with
the fitted normal distribution, the mean absolute difference between them,
and a normality test; for the pair, a two-sample Kolmogorov-Smirnov test; and
the 90 % interval (§3.2: [-13.38, 14.28]° and [-14.07, 15.15]°).

Normality is tested with Lilliefors' test (``statsmodels``), the
Kolmogorov-Smirnov test with the mean and variance estimated from the same
data; a plain KS test against a normal with fitted parameters would be far
too lenient.  Both tests assume independent samples, and ``u_d`` is
correlated from one 0.1 s interval to the next, so the tests see the trace
thinned to every ``stride``-th value, ``stride`` being the first lag at which
the sample autocorrelation falls below :data:`DECORRELATION`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats
from scipy.fft import next_fast_len

from identification.model import Disturbance
from rocketroll_common.arrays import FloatArray

__all__ = [
    "DisturbanceStatistics",
    "TraceStatistics",
    "decorrelation_stride",
    "newey_west_covariance",
    "newey_west_lags",
    "newey_west_meat",
    "ols_newey_west",
    "trace_statistics",
    "two_stage_least_squares",
]

#: Autocorrelation below which two samples are treated as independent.
DECORRELATION = 0.1
#: Significance level of the tests.
ALPHA = 0.05


def newey_west_meat(scores: FloatArray, lags: int) -> FloatArray:
    """The Newey-West sandwich's inner matrix ``Σ_{|j|<=L} (1 - |j|/(L+1)) Γ_j`` of the
    score rows ``scores`` (n × k, consecutive in time), ``Γ_j = Σ_t z_{t+j} z_tᵀ``:
    statsmodels' ``S_hac_simple(scores, nlags=lags)`` (Bartlett weights) in ``O(n k)``
    rather than one product per lag.

    The Bartlett weights times ``L + 1`` are the overlap of two boxcars of ``L + 1``
    readings, so the weighted sum of lags is ``YᵀY / (L + 1)`` with ``Y`` the running sums
    of ``L + 1`` consecutive scores (positive semi-definite, as Bartlett's always is)."""
    z = np.atleast_2d(np.asarray(scores, dtype=float).T)  # k × n: sums along rows
    n = z.shape[1]
    lags = max(0, min(int(lags), n - 1))
    zero = np.zeros((z.shape[0], 1))
    total = np.concatenate([zero, np.cumsum(z, axis=1)], axis=1)  # total[:, t] = Σ_{s<t} z_s
    end = np.concatenate([total[:, 1:], np.repeat(total[:, -1:], lags, axis=1)], axis=1)
    start = np.concatenate([np.repeat(zero, lags, axis=1), total[:, :n]], axis=1)
    running = end - start  # column t < n + L: Σ_{s=t-L..t} z_s (zero outside the record)
    return np.asarray(running @ running.T / (lags + 1))


def ols_newey_west(x: FloatArray, y: FloatArray, lags: int) -> tuple[FloatArray, ...]:
    """Least squares of ``y`` on the columns of ``x`` (by QR) with the Newey-West covariance
    of the coefficients over ``lags`` (Bartlett weights, no small-sample factor: statsmodels'
    ``OLS(...).fit(cov_type="HAC")``): ``(beta, residuals, covariance)``.  Raises
    ``numpy.linalg.LinAlgError`` where ``x`` is rank deficient."""
    q, r = np.linalg.qr(x)
    r_inv = np.linalg.inv(r)
    beta = r_inv @ (q.T @ y)
    resid = y - x @ beta
    bread = r_inv @ r_inv.T  # (XᵀX)⁻¹
    return beta, resid, bread @ newey_west_meat(x * resid[:, None], lags) @ bread


def newey_west_lags(residuals: FloatArray, at_least: int = 1) -> int:
    """The lags of a Newey-West covariance for a fit whose ``residuals`` are correlated in
    time: four times their correlation length (the first lag whose autocorrelation is under
    1/e), at least ``at_least`` and at most a quarter of their number (one for fewer than
    eight)."""
    stride = decorrelation_stride(residuals, math.exp(-1.0))
    return min(max(4 * stride, at_least), max(residuals.size // 4, 1))


def newey_west_covariance(design: FloatArray, residuals: FloatArray, lags: int) -> FloatArray:
    """The sandwich ``(DᵀD)⁻¹ S (DᵀD)⁻¹`` of a least-squares fit with design (or Jacobian)
    ``D`` and ``residuals``, ``S`` the Newey-West meat of their scores over ``lags``
    (:func:`newey_west_meat`; no small-sample factor).  Raises
    ``numpy.linalg.LinAlgError`` where ``DᵀD`` is singular."""
    bread = np.linalg.inv(design.T @ design)
    return bread @ newey_west_meat(design * residuals[:, None], lags) @ bread


def two_stage_least_squares(
    x: FloatArray, y: FloatArray, z: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Two-stage least squares of ``y`` on the columns of ``x`` with instruments ``z`` (the
    exogenous columns of ``x`` among them; statsmodels' ``IV2SLS``): ``(beta, residuals,
    projected)``, the residuals those of ``x`` itself and ``projected`` ``x`` projected on
    the instruments, the design of the covariance (:func:`newey_west_covariance`).  Raises
    ``numpy.linalg.LinAlgError`` where the first stage is rank deficient."""
    q, _ = np.linalg.qr(z)
    projected = q @ (q.T @ x)
    beta = np.linalg.inv(projected.T @ projected) @ (projected.T @ y)
    return beta, y - x @ beta, projected


def decorrelation_stride(x: ArrayLike, threshold: float = DECORRELATION) -> int:
    """First lag at which the sample autocorrelation of ``x`` is below ``threshold``."""
    y = np.asarray(x, dtype=float)
    y = y - y.mean()
    n = y.size
    if n < 3 or not np.any(y):
        return 1
    # Zero-padded to at least 2n - 1 (a linear, not circular, correlation), at a length the
    # FFT factors well.
    size = next_fast_len(2 * n, real=True)
    spectrum = np.fft.rfft(y, size)
    acf = np.fft.irfft(spectrum * np.conj(spectrum), size)[: n // 2]
    acf = acf / acf[0]
    below = np.flatnonzero(acf < threshold)
    return int(below[0]) if below.size else max(1, n // 2)


@dataclass(frozen=True, eq=False)
class TraceStatistics:
    """Distribution of one ``u_d`` trace.

    Attributes
    ----------
    mean_deg, sd_deg : float
        Mean and SD (the fitted normal), °.
    q05_deg, q95_deg : float
        The 90 % interval, °.
    bin_edges_deg : ndarray
        Histogram bins (Freedman-Diaconis), °.
    density : ndarray
        Normalised histogram (area 1), 1/°.
    normal_density : ndarray
        Fitted normal pdf at the bin centres, 1/°.
    histogram_mad : float
        Mean absolute difference between ``density`` and ``normal_density``,
        1/° (the paper: 0.0278 and 0.0294).
    stride : int
        Thinning used for the normality test.
    lilliefors_stat, lilliefors_p : float
        Lilliefors normality test on the thinned trace.
    normal : bool
        ``lilliefors_p >= 0.05``: no significant departure from normality.
    """

    mean_deg: float
    sd_deg: float
    q05_deg: float
    q95_deg: float
    bin_edges_deg: FloatArray
    density: FloatArray
    normal_density: FloatArray
    histogram_mad: float
    stride: int
    lilliefors_stat: float
    lilliefors_p: float

    @property
    def normal(self) -> bool:
        """No significant departure from normality at the 5 % level."""
        return self.lilliefors_p >= ALPHA

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe summary (without the histogram)."""
        return {
            "mean_deg": self.mean_deg,
            "sd_deg": self.sd_deg,
            "interval90_deg": [self.q05_deg, self.q95_deg],
            "histogram_mad": self.histogram_mad,
            "stride": self.stride,
            "lilliefors_stat": self.lilliefors_stat,
            "lilliefors_p": self.lilliefors_p,
            "normal": self.normal,
        }


def trace_statistics(u_d_deg: ArrayLike) -> TraceStatistics:
    """Histogram, fitted normal, 90 % interval and Lilliefors test of one trace."""
    from statsmodels.stats.diagnostic import lilliefors

    x = np.asarray(u_d_deg, dtype=float)
    mean, sd = float(x.mean()), float(x.std(ddof=1))
    q05, q95 = np.percentile(x, [5, 95])
    density, edges = np.histogram(x, bins="fd", density=True)
    centres = 0.5 * (edges[1:] + edges[:-1])
    normal = stats.norm.pdf(centres, mean, sd)
    stride = decorrelation_stride(x)
    thinned = x[::stride]
    if thinned.size >= 4 and sd > 0:
        stat, p = lilliefors(thinned, dist="norm", pvalmethod="table")
    else:
        stat, p = float("nan"), float("nan")
    return TraceStatistics(
        mean_deg=mean,
        sd_deg=sd,
        q05_deg=float(q05),
        q95_deg=float(q95),
        bin_edges_deg=edges,
        density=density,
        normal_density=normal,
        histogram_mad=float(np.mean(np.abs(density - normal))),
        stride=stride,
        lilliefors_stat=float(stat),
        lilliefors_p=float(p),
    )


@dataclass(frozen=True, eq=False)
class DisturbanceStatistics:
    """§3.4 for both traces and their comparison.

    Attributes
    ----------
    theta, constant : TraceStatistics
        ``u_d,θ`` and ``u_d,constant``.
    ks_stat, ks_p : float
        Two-sample Kolmogorov-Smirnov test between the two traces (thinned
        with the larger of their strides).
    """

    theta: TraceStatistics
    constant: TraceStatistics
    ks_stat: float
    ks_p: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe summary."""
        return {
            "theta": self.theta.to_dict(),
            "constant": self.constant.to_dict(),
            "ks_two_sample": {"stat": self.ks_stat, "p": self.ks_p},
        }


def disturbance_statistics(theta: Disturbance, constant: Disturbance) -> DisturbanceStatistics:
    """Step 11: statistics of ``u_d,θ`` and ``u_d,constant`` (§3.4)."""
    st = trace_statistics(theta.u_d_deg)
    sc = trace_statistics(constant.u_d_deg)
    stride = max(st.stride, sc.stride)
    ks = stats.ks_2samp(theta.u_d_deg[::stride], constant.u_d_deg[::stride])
    return DisturbanceStatistics(
        theta=st, constant=sc, ks_stat=float(ks.statistic), ks_p=float(ks.pvalue)
    )
