"""Surrogate disturbance traces: new ``u_d(t)`` with the statistics of a recorded one.

An identified disturbance trace (``u_d`` in degrees of equivalent fin angle,
one sample per 0.1 s) is a single realisation.  Training or testing a
controller on it alone over-fits that realisation, so this module makes new
traces that keep its two properties that matter for roll dynamics: the
amplitude distribution (marginal) and the power spectrum (equivalently the
autocorrelation).  Two methods are offered.

IAAFT (:func:`iaaft`)
    The Iterative Amplitude Adjusted Fourier Transform of Schreiber and
    Schmitz [1]_.  Starting from a random permutation of the source, it
    alternately imposes the source's Fourier amplitudes (keeping the current
    phases) and the source's exact amplitude distribution (rank-order remap
    onto the sorted source values), until the rank order stops changing.  The
    result is a permutation of the source, so the marginal is kept *exactly*,
    and its spectrum matches the source's to within a small residual error.
    It is non-parametric, but it cannot produce values outside those
    recorded, and it treats the trace as periodic.

AR (:func:`fit_ar`, :func:`ar_surrogate`)
    An autoregressive model ``u_t = c + sum_k a_k u_{t-k} + e_t`` whose order
    is chosen by AIC among ``statsmodels``' ``AutoReg`` fits, as ``ar_select_order``
    chooses it [2]_, simulated with innovations either Gaussian with the fitted
    innovation SD (the default) or resampled from the fitted residuals
    (bootstrap; it keeps more of a non-Gaussian marginal).  The spectrum is the
    AR's (a smooth parametric estimate of the source's); the marginal is
    only approximately the source's, but the traces can be of any length and
    take values never recorded.

Validation (:func:`check_surrogate`)
    A surrogate is accepted when

    * its marginal is not distinguishable from the source's: two-sample
      Kolmogorov-Smirnov test, not rejected at :data:`KS_ALPHA`.  KS assumes
      independent samples, so both traces are first thinned to every
      ``stride``-th value, ``stride`` being the source's decorrelation lag
      (:func:`identification.methods.statistics.decorrelation_stride`);
    * its power spectrum is close to the source's: the RMS over frequencies
      (DC excluded) of ``log10(P_surrogate / P_source)`` between Welch [3]_
      estimates, in decades, is at most :data:`PSD_TOLERANCE_DECADES`.

References
----------
.. [1] T. Schreiber and A. Schmitz, "Improved surrogate data for
   nonlinearity tests", Phys. Rev. Lett. 77, 635-638 (1996).
.. [2] statsmodels, ``statsmodels.tsa.ar_model.AutoReg`` and
   ``ar_select_order``; H. Akaike, "A new look at the statistical model
   identification", IEEE Trans. Autom. Control 19, 716-723 (1974).
.. [3] P. D. Welch, "The use of fast Fourier transform for the estimation of
   power spectra", IEEE Trans. Audio Electroacoust. 15, 70-73 (1967).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import signal, stats
from statsmodels.tsa.ar_model import AutoReg, ar_select_order

from identification.estimation.likelihood import select_order
from identification.methods.statistics import decorrelation_stride
from rocketroll_common.arrays import readonly_array

__all__ = [
    "CHECK_NPERSEG",
    "KS_ALPHA",
    "MIN_SAMPLES",
    "PSD_TOLERANCE_DECADES",
    "ARModel",
    "Surrogate",
    "SurrogateCheck",
    "ar_surrogate",
    "check_surrogate",
    "checked_min_samples",
    "fit_ar",
    "iaaft",
    "make_surrogate",
]

FloatArray = NDArray[np.float64]
Method = Literal["iaaft", "ar"]
Innovations = Literal["bootstrap", "gaussian"]

#: Significance level of the two-sample KS test on the thinned marginals.
KS_ALPHA = 0.05

#: Largest accepted RMS of ``log10(P_surrogate / P_source)`` over frequencies
#: (DC excluded), in decades, for Welch PSDs with ``nperseg=256``.
#:
#: Measured on the identified ``u_d,θ`` of all seven bundled recordings
#: (``tunnel-paper-seed0..4``, 5730 samples; ``tunnel-staircase-seed10/11``,
#: 5466 / 4498 samples; 0.1 s; the source spectra span 5-6 decades from
#: 0.04 to 5 Hz), as min / median / max:
#:
#: * IAAFT, 100 seeds per trace: 0.029 / 0.043 / 0.154 (paper-seed0, Gaussian),
#:   0.036 / 0.095 / 0.361 (paper-seed3, Laplace; 95th percentile 0.264), at
#:   most 0.192 on the other five.  The excess is high-frequency power, four
#:   decades below the peak, left by the rank-order remap when an unlucky
#:   starting permutation settles on a poorer fixed point;
#: * AR, 50 seeds per trace: bootstrap innovations 0.068 / ~0.10 / 0.154,
#:   Gaussian innovations 0.071 / ~0.09 / 0.120 (all traces);
#: * wrong traces: white noise of the source's mean and SD 2.34-2.58; the
#:   source shuffled 2.33-2.59; the source low-pass filtered much harder
#:   (4th-order Butterworth at 0.3 Hz, zero phase, rescaled to the source SD)
#:   6.98-7.54; an AR(1) with the source's lag-1 correlation 1.06-1.33; the
#:   source stretched in time by 1.25 (correlation time 25 % longer) 0.53-0.73,
#:   by 1.5 0.76-0.96.
#:
#: The tolerance sits between the worst good surrogate (0.36) and the mildest
#: wrong trace tried (0.53); the obviously wrong ones are 5-15 times above it.
PSD_TOLERANCE_DECADES = 0.45

#: Shortest trace a surrogate is made from, samples.
MIN_SAMPLES = 64

#: Burn-in of the AR simulation when not given: long enough for the slowest
#: mode of the fitted AR to decay to this fraction, and at least
#: :data:`_MIN_BURN_IN` samples.
_BURN_IN_DECAY = 1e-8
_MIN_BURN_IN = 100


# --------------------------------------------------------------------------- results


@dataclass(frozen=True, eq=False)
class Surrogate:
    """A surrogate ``u_d`` trace.

    Attributes
    ----------
    method : {"iaaft", "ar"}
        How it was made.
    u_d_deg : ndarray, shape (n,)
        The trace, ° of equivalent fin angle, same sampling as the source
        (read-only float64 copy).
    settings : dict
        JSON-safe record of the method's parameters and outcome (IAAFT:
        ``max_iter``, ``rtol``, ``iterations``, ``stop``, ``spectral_error``;
        AR: ``max_order``, ``order``, ``const``, ``coefs``, ``sigma``,
        ``innovations``, ``burn_in``).
    """

    method: Method
    u_d_deg: FloatArray
    settings: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.method not in ("iaaft", "ar"):
            raise ValueError(f"unknown surrogate method {self.method!r}; use 'iaaft' or 'ar'")
        object.__setattr__(self, "u_d_deg", readonly_array(self.u_d_deg))
        object.__setattr__(self, "settings", dict(self.settings))


@dataclass(frozen=True, eq=False)
class ARModel:
    """An autoregressive model ``u_t = const + sum_k coefs[k-1] u_{t-k} + e_t``.

    Attributes
    ----------
    order : int
        Number of lags ``p`` (0: white noise around ``const``).
    const : float
        Intercept ``c``, °.
    coefs : ndarray, shape (p,)
        Lag coefficients ``a_1 .. a_p`` (read-only).
    sigma : float
        Innovation SD, ° (``sqrt`` of statsmodels' ``sigma2``).
    residuals : ndarray, shape (n - p,)
        In-sample one-step residuals, ° (read-only).
    """

    order: int
    const: float
    coefs: FloatArray
    sigma: float
    residuals: FloatArray

    def __post_init__(self) -> None:
        object.__setattr__(self, "coefs", readonly_array(self.coefs))
        object.__setattr__(self, "residuals", readonly_array(self.residuals))

    @property
    def poles(self) -> NDArray[np.complex128]:
        """Roots of ``z^p - a_1 z^(p-1) - ... - a_p`` (inside the unit circle if stationary)."""
        if self.order == 0:
            return np.zeros(0, dtype=complex)
        return np.roots(np.concatenate(([1.0], -self.coefs))).astype(complex)

    @property
    def stationary(self) -> bool:
        """All poles strictly inside the unit circle."""
        return bool(np.all(np.abs(self.poles) < 1.0))

    @property
    def mean(self) -> float:
        """Process mean ``c / (1 - sum a_k)``, ° (meaningful when stationary)."""
        return self.const / (1.0 - float(np.sum(self.coefs)))

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe summary (without the residuals)."""
        return {
            "order": self.order,
            "const": self.const,
            "coefs": [float(a) for a in self.coefs],
            "sigma": self.sigma,
        }


@dataclass(frozen=True)
class SurrogateCheck:
    """How close a surrogate is to its source (see :func:`check_surrogate`).

    Attributes
    ----------
    ks_stat, ks_p : float
        Two-sample Kolmogorov-Smirnov statistic and p-value between the two
        marginals, both thinned to every ``stride``-th sample.
    psd_log_distance : float
        RMS over the Welch frequencies (DC excluded) of
        ``log10(P_surrogate / P_source)``, decades.
    stride : int
        Decorrelation stride of the source, samples.
    nperseg : int
        Welch segment length, samples.
    """

    ks_stat: float
    ks_p: float
    psd_log_distance: float
    stride: int
    nperseg: int

    @property
    def ks_passed(self) -> bool:
        """The marginals are not distinguishable at :data:`KS_ALPHA`."""
        return self.ks_p >= KS_ALPHA

    @property
    def psd_passed(self) -> bool:
        """The spectra agree to within :data:`PSD_TOLERANCE_DECADES`."""
        return self.psd_log_distance <= PSD_TOLERANCE_DECADES

    @property
    def passed(self) -> bool:
        """Both the marginal and the spectrum are accepted."""
        return self.ks_passed and self.psd_passed

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe summary, with the thresholds used."""
        return {
            "ks_stat": self.ks_stat,
            "ks_p": self.ks_p,
            "ks_alpha": KS_ALPHA,
            "psd_log_distance": self.psd_log_distance,
            "psd_tolerance_decades": PSD_TOLERANCE_DECADES,
            "stride": self.stride,
            "nperseg": self.nperseg,
            "ks_passed": self.ks_passed,
            "psd_passed": self.psd_passed,
            "passed": self.passed,
        }


# --------------------------------------------------------------------------- validation


def _trace(x: ArrayLike, name: str = "x", min_samples: int = MIN_SAMPLES) -> FloatArray:
    """``x`` as a 1-D float64 array, checked for length, NaN/inf and variation."""
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be a 1-D trace, got an array of shape {arr.shape}")
    if arr.size < min_samples:
        raise ValueError(
            f"{name} is too short: {arr.size} samples, at least {min_samples} are needed"
        )
    if not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise ValueError(f"{name} contains {bad} NaN or infinite value(s)")
    if np.ptp(arr) == 0.0:
        raise ValueError(f"{name} is constant; a surrogate needs a varying trace")
    return arr


def _generator(rng: object) -> np.random.Generator:
    if not isinstance(rng, np.random.Generator):
        raise TypeError(
            f"rng must be a numpy.random.Generator (np.random.default_rng(seed)), "
            f"not {type(rng).__name__}"
        )
    return rng


# --------------------------------------------------------------------------- IAAFT


def iaaft(
    x: ArrayLike,
    rng: np.random.Generator,
    *,
    max_iter: int = 1000,
    rtol: float = 1e-8,
) -> Surrogate:
    """Iterative Amplitude Adjusted Fourier Transform surrogate of ``x``.

    Parameters
    ----------
    x : array_like, shape (n,)
        Source trace (finite, not constant, at least :data:`MIN_SAMPLES`).
    rng : numpy.random.Generator
        Draws the initial random permutation; the only randomness.
    max_iter : int, optional
        Most iterations (each: one spectrum and one rank-order step).
    rtol : float, optional
        Also stop when the relative change of the spectral error between two
        iterations is at most ``rtol``.

    Returns
    -------
    Surrogate
        ``method="iaaft"``; ``u_d_deg`` is a permutation of ``x`` (the
        amplitude distribution is kept exactly).  ``settings`` holds
        ``max_iter``, ``rtol``, ``iterations`` (used), ``stop``
        (``"ranks"``: the rank order no longer changed; ``"rtol"``: the
        spectral error stalled; ``"max_iter"``) and ``spectral_error`` (RMS
        of the Fourier-amplitude mismatch relative to the RMS Fourier
        amplitude of ``x``).

    Raises
    ------
    ValueError
        ``x`` is not a finite, varying 1-D trace of at least
        :data:`MIN_SAMPLES` samples, or ``max_iter < 1`` or ``rtol < 0``.
    TypeError
        ``rng`` is not a :class:`numpy.random.Generator`.

    Notes
    -----
    The algorithm of Schreiber and Schmitz [1]_.  With ``s`` the sorted
    source values and ``|X_k|`` its Fourier amplitudes (``rfft``), starting
    from ``y = permutation(x)``:

    1. ``Y = rfft(y)``; ``z = irfft(|X_k| * Y_k / |Y_k|)`` (spectrum imposed,
       phases kept);
    2. ``y[argsort(z)] = s`` (amplitude distribution imposed, ranks of ``z``
       kept);

    until ``y`` stops changing.  The spectrum-imposed ``z`` would have the
    exact spectrum but not the exact marginal; the returned ``y`` has the
    exact marginal and a spectrum within ``spectral_error`` of the source's.

    References
    ----------
    .. [1] T. Schreiber and A. Schmitz, "Improved surrogate data for
       nonlinearity tests", Phys. Rev. Lett. 77, 635-638 (1996).

    Examples
    --------
    >>> import numpy as np
    >>> x = np.cumsum(np.random.default_rng(0).standard_normal(512))
    >>> s = iaaft(x, np.random.default_rng(1))
    >>> bool(np.array_equal(np.sort(s.u_d_deg), np.sort(x)))
    True
    """
    source = _trace(x)
    rng = _generator(rng)
    if max_iter < 1:
        raise ValueError(f"max_iter must be at least 1, got {max_iter}")
    if not rtol >= 0.0:
        raise ValueError(f"rtol must be non-negative, got {rtol}")

    n = source.size
    sorted_values = np.sort(source)
    amplitude = np.abs(np.fft.rfft(source))
    amplitude_rms = float(np.sqrt(np.mean(amplitude**2)))

    y = rng.permutation(source)
    spectrum = np.fft.rfft(y)
    error = math.inf
    stop = "max_iter"
    iterations = 0
    while iterations < max_iter:
        iterations += 1
        # Impose the source's Fourier amplitudes, keeping the current phases.
        modulus = np.abs(spectrum)
        phase = np.divide(spectrum, modulus, out=np.ones_like(spectrum), where=modulus > 0.0)
        z = np.fft.irfft(amplitude * phase, n)
        # Impose the source's values in the rank order of z.
        y_next = np.empty_like(y)
        y_next[np.argsort(z, kind="stable")] = sorted_values
        spectrum = np.fft.rfft(y_next)
        new_error = float(np.sqrt(np.mean((np.abs(spectrum) - amplitude) ** 2))) / amplitude_rms
        unchanged = np.array_equal(y_next, y)
        stalled = abs(error - new_error) <= rtol * new_error
        y, error = y_next, new_error
        if unchanged:
            stop = "ranks"
            break
        if stalled:
            stop = "rtol"
            break

    settings = {
        "max_iter": int(max_iter),
        "rtol": float(rtol),
        "iterations": int(iterations),
        "stop": stop,
        "spectral_error": error,
    }
    return Surrogate(method="iaaft", u_d_deg=y, settings=settings)


# --------------------------------------------------------------------------- AR


def _check_max_order(max_order: int) -> None:
    if max_order < 0:
        raise ValueError(f"max_order must be non-negative, got {max_order}")


def _ar_min_samples(max_order: int) -> int:
    """Shortest trace an AR of up to ``max_order`` lags is fitted to."""
    return max(MIN_SAMPLES, 3 * max_order)


def fit_ar(x: ArrayLike, *, max_order: int = 30) -> ARModel:
    """Fit an autoregressive model to ``x``, its order chosen by AIC.

    Parameters
    ----------
    x : array_like, shape (n,)
        Source trace (finite, not constant, at least
        ``max(MIN_SAMPLES, 3 * max_order)`` samples).
    max_order : int, optional
        Largest order tried.

    Returns
    -------
    ARModel
        The AIC-best model among orders ``0 .. max_order`` (contiguous lags,
        constant trend), fitted by conditional least squares.

    Raises
    ------
    ValueError
        ``x`` is not a finite, varying 1-D trace long enough, or
        ``max_order < 0``.

    Notes
    -----
    ``statsmodels.tsa.ar_model.ar_select_order(x, max_order, ic="aic", trend="c")`` gives
    the AIC of every order, all on the same sample (the first ``max_order`` values held
    back); the order is the one of least AIC among them
    (:func:`identification.estimation.likelihood.select_order`, the toolkit's one order
    selection, the first of equals as statsmodels keeps it); then
    ``AutoReg(x, lags, trend="c")`` refits on all the data [1]_.

    References
    ----------
    .. [1] H. Akaike, "A new look at the statistical model identification",
       IEEE Trans. Autom. Control 19, 716-723 (1974).
    """
    _check_max_order(max_order)
    source = _trace(x, min_samples=_ar_min_samples(max_order))
    order = 0
    if max_order > 0:
        # statsmodels' AIC of every order on one sample (the first max_order values held
        # back), keyed 0, (1,), (1, 2), ...; the toolkit's one selection picks among them
        aic = ar_select_order(source, maxlag=max_order, ic="aic", trend="c").aic
        order = select_order(
            lambda p: (float(aic[tuple(range(1, p + 1)) or 0]), p), range(max_order + 1)
        )[0]
    lags = list(range(1, order + 1))
    result = AutoReg(source, lags=lags if lags else 0, trend="c").fit()
    params = np.asarray(result.params, dtype=np.float64)
    return ARModel(
        order=order,
        const=float(params[0]),
        coefs=params[1:],
        sigma=float(np.sqrt(result.sigma2)),
        residuals=np.asarray(result.resid, dtype=np.float64),
    )


def _default_burn_in(model: ARModel) -> int:
    """Samples for the slowest mode of ``model`` to decay to :data:`_BURN_IN_DECAY`."""
    radius = float(np.max(np.abs(model.poles), initial=0.0))
    if radius <= 0.0:
        return _MIN_BURN_IN
    return max(_MIN_BURN_IN, math.ceil(math.log(_BURN_IN_DECAY) / math.log(radius)))


def ar_surrogate(
    x: ArrayLike,
    rng: np.random.Generator,
    *,
    max_order: int = 30,
    innovations: Innovations = "gaussian",
    burn_in: int | None = None,
) -> Surrogate:
    """Surrogate of ``x`` simulated from an AR model fitted to it.

    Parameters
    ----------
    x : array_like, shape (n,)
        Source trace (see :func:`fit_ar`).
    rng : numpy.random.Generator
        Draws the innovations; the only randomness.
    max_order : int, optional
        Largest AR order tried (:func:`fit_ar`).
    innovations : {"bootstrap", "gaussian"}, optional
        ``"gaussian"`` (default): normal with the fitted innovation SD;
        ``"bootstrap"``: resampled with replacement from the fitted
        residuals, which keeps more of a non-Gaussian marginal.  Gaussian
        is the default because an identified trace's residuals carry the
        identification's artefacts at the fin steps (excess kurtosis about
        27 on ``tunnel-paper-seed0``); resampled, they spread heavy tails
        over the whole surrogate, and KS rejected 27.5 % of bootstrap
        surrogates of that Gaussian trace against 13 % with Gaussian
        innovations (200 seeds).  For a clearly non-Gaussian source
        (``tunnel-paper-seed3``, Laplace) bootstrap does better: 1 % against
        17.5 %.
    burn_in : int, optional
        Leading simulated samples discarded.  Default: until the slowest
        mode of the fitted model has decayed by a factor ``1e8`` (at least
        100 samples).

    Returns
    -------
    Surrogate
        ``method="ar"``, ``n`` samples like ``x``.  ``settings`` holds
        ``max_order``, ``innovations``, ``burn_in`` and the model
        (``order``, ``const``, ``coefs``, ``sigma``).

    Raises
    ------
    ValueError
        Bad ``x`` (see :func:`fit_ar`), unknown ``innovations``, negative
        ``burn_in``, or a fitted model that is not stationary.
    TypeError
        ``rng`` is not a :class:`numpy.random.Generator`.

    Notes
    -----
    The recursion ``u_t - mu = sum_k a_k (u_{t-k} - mu) + e_t`` is run by
    :func:`scipy.signal.lfilter` (denominator ``[1, -a_1, ..., -a_p]``) from
    rest at the process mean ``mu``; the burn-in removes the start-up
    transient of the variance.
    """
    rng = _generator(rng)
    if innovations not in ("bootstrap", "gaussian"):
        raise ValueError(f"innovations must be 'bootstrap' or 'gaussian', got {innovations!r}")
    if burn_in is not None and burn_in < 0:
        raise ValueError(f"burn_in must be non-negative, got {burn_in}")
    model = fit_ar(x, max_order=max_order)
    if not model.stationary:
        raise ValueError(
            f"the fitted AR({model.order}) model is not stationary "
            f"(largest pole modulus {np.max(np.abs(model.poles)):.4f}); "
            "use the IAAFT method for this trace"
        )
    n = np.asarray(x).size
    n_burn = _default_burn_in(model) if burn_in is None else int(burn_in)
    total = n + n_burn
    if innovations == "bootstrap":
        residuals = model.residuals - model.residuals.mean()
        e = rng.choice(residuals, size=total, replace=True)
    else:
        e = rng.normal(0.0, model.sigma, size=total)
    denominator = np.concatenate(([1.0], -model.coefs))
    u = signal.lfilter([1.0], denominator, e)[n_burn:] + model.mean

    settings: dict[str, Any] = {
        "max_order": int(max_order),
        "innovations": innovations,
        "burn_in": n_burn,
        **model.to_dict(),
    }
    return Surrogate(method="ar", u_d_deg=np.asarray(u, dtype=np.float64), settings=settings)


# --------------------------------------------------------------------------- dispatch


def make_surrogate(x: ArrayLike, method: str, rng: np.random.Generator, **kw: Any) -> Surrogate:
    """A surrogate of ``x`` by ``method``.

    Parameters
    ----------
    x : array_like, shape (n,)
        Source trace, ° (finite, not constant, at least :data:`MIN_SAMPLES`).
    method : {"iaaft", "ar"}
        :func:`iaaft` or :func:`ar_surrogate`.
    rng : numpy.random.Generator
        The only source of randomness.
    **kw
        Keyword arguments of the chosen method.

    Returns
    -------
    Surrogate

    Raises
    ------
    ValueError
        Unknown ``method``; ``x`` too short, not 1-D, constant, or with NaN
        or infinite values; bad method arguments.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.sin(np.arange(200) / 5.0)
    >>> make_surrogate(x, "iaaft", np.random.default_rng(0)).method
    'iaaft'
    """
    if method == "iaaft":
        return iaaft(x, rng, **kw)
    if method == "ar":
        return ar_surrogate(x, rng, **kw)
    raise ValueError(f"unknown surrogate method {method!r}; use 'iaaft' or 'ar'")


# --------------------------------------------------------------------------- check


#: Welch segment of :func:`check_surrogate`, samples.
CHECK_NPERSEG = 256


def checked_min_samples(nperseg: int = CHECK_NPERSEG) -> int:
    """Fewest samples a trace needs for its surrogates to be checked (two Welch segments)."""
    return max(MIN_SAMPLES, 2 * nperseg)


def check_surrogate(
    source: ArrayLike,
    surrogate: Surrogate | ArrayLike,
    dt_s: float,
    *,
    nperseg: int = CHECK_NPERSEG,
) -> SurrogateCheck:
    """Compare a surrogate's marginal and spectrum with its source's.

    Parameters
    ----------
    source : array_like, shape (n,)
        The recorded trace, °.
    surrogate : Surrogate or array_like, shape (m,)
        The surrogate (or any trace to test against ``source``).
    dt_s : float
        Sampling interval of both, s.
    nperseg : int, optional
        Welch segment length; both traces need at least ``2 * nperseg``
        samples.

    Returns
    -------
    SurrogateCheck
        KS statistic and p-value on the thinned marginals, the PSD log
        distance, the stride; ``passed`` when ``ks_p >= KS_ALPHA`` and
        ``psd_log_distance <= PSD_TOLERANCE_DECADES``.

    Raises
    ------
    ValueError
        A trace that is too short, not 1-D, constant or not finite;
        ``dt_s <= 0``; ``nperseg < 8``.

    Notes
    -----
    * Marginal: ``scipy.stats.ks_2samp(source[::stride],
      surrogate[::stride])`` with ``stride =
      decorrelation_stride(source)`` (first lag at which the source's
      autocorrelation is below 0.1), since the test assumes independent
      samples; on the unthinned, correlated traces it would reject far too
      often.
    * Spectrum: ``scipy.signal.welch`` (Hann window, 50 % overlap, mean
      removed, ``fs = 1 / dt_s``) of both; the distance is
      ``sqrt(mean(log10(P_surrogate / P_source) ** 2))`` over all
      frequencies but DC [1]_.

    References
    ----------
    .. [1] P. D. Welch, "The use of fast Fourier transform for the
       estimation of power spectra", IEEE Trans. Audio Electroacoust. 15,
       70-73 (1967).
    """
    if nperseg < 8:
        raise ValueError(f"nperseg must be at least 8, got {nperseg}")
    if not (math.isfinite(dt_s) and dt_s > 0.0):
        raise ValueError(f"dt_s must be a positive sampling interval, got {dt_s}")
    minimum = checked_min_samples(nperseg)
    src = _trace(source, "source", minimum)
    values = surrogate.u_d_deg if isinstance(surrogate, Surrogate) else surrogate
    sur = _trace(values, "surrogate", minimum)

    stride = decorrelation_stride(src)
    ks = stats.ks_2samp(src[::stride], sur[::stride])

    fs = 1.0 / dt_s
    _, p_src = signal.welch(src, fs=fs, nperseg=nperseg)
    _, p_sur = signal.welch(sur, fs=fs, nperseg=nperseg)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_ratio = np.log10(p_sur[1:]) - np.log10(p_src[1:])
    distance = float(np.sqrt(np.mean(log_ratio**2)))
    if not math.isfinite(distance):
        distance = math.inf

    return SurrogateCheck(
        ks_stat=float(ks.statistic),
        ks_p=float(ks.pvalue),
        psd_log_distance=distance,
        stride=int(stride),
        nperseg=int(nperseg),
    )
