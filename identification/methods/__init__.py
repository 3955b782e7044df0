"""Identification methods: one registry behind one ``method=`` keyword.

A method turns a recording into, for each damping model (:data:`MODELS
<identification.model.MODELS>`), the rocket's parameters, the disturbance
``u_d(t)`` that goes with them and fit metrics: a :class:`ModelFit`.  The
paper's integral least squares (``"paper"``) and the output-error peer
(``"output-error"``) are registered here; :func:`register_method` adds
another, and the command line (``rocketroll identify --method``,
``rocketroll db add --method``), the disturbance database, the default
database's recipe and the benchmarks find it::

    from identification.methods import ModelFit, register_method

    def my_method(context, models):
        inputs = context.measurements  # steps 1 and 5: fin steps, velocity, fin angle
        ...
        return [ModelFit("mine", model, params, disturbance, metrics) for model in models]

    register_method("mine", my_method, summary="my estimator")

:func:`fit` runs a method by name, as python-control's ``method=`` keywords
do.  A :class:`Context` is shared by all methods run on one recording, so
the measurements are prepared, and the paper's pipeline run, at most once.

The methods live beside the registry: the paper's steps
(:mod:`~identification.methods.steps`, eq. by eq.), its pipeline
(:mod:`~identification.methods.pipeline`), its noise study and statistics;
output error (:mod:`~identification.methods.baselines`); maximum likelihood in the
tunnel (:mod:`~identification.methods.ml` on :mod:`~identification.methods.rollspace`) and in
flight (:mod:`~identification.methods.flight` on :mod:`~identification.methods.flightfit`),
both on the estimation core; the
fin's linkage, latency and quadratic damping (:mod:`~identification.methods.actuation`);
and every fit's adequacy (:mod:`~identification.methods.adequacy`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from identification.model import MODEL_NAMES, RollParams, check_model
from identification.recordings.recording import Recording
from rocketroll_common.arrays import FloatArray
from rocketroll_common.registry import Registry

if TYPE_CHECKING:
    from identification.methods.pipeline import Identification, IdentifyOptions, Measurements
    from identification.methods.steps import Resimulation
    from identification.model import Disturbance

__all__ = [
    "METHODS",
    "Context",
    "MethodFunction",
    "MethodTraits",
    "ModelFit",
    "database_methods",
    "default_methods",
    "fit",
    "has_posterior",
    "is_flight_method",
    "paper_method",
    "register_method",
    "resimulation_metrics",
    "trace_settings",
    "traits",
    "tunnel_methods",
]


@dataclass(frozen=True, eq=False)
class ModelFit:
    """What a method found for one damping model of one recording.

    Attributes
    ----------
    method : str
        The method's registered name.
    model : str
        ``constant`` or ``theta``.
    params : RollParams
        The rocket's parameters.
    disturbance : Disturbance
        ``u_d(t)`` that goes with them (held over each interval).
    metrics : mapping
        Fit metrics, JSON-safe (re-simulation errors, the method's own).
    trace_settings : mapping
        How ``u_d`` was obtained, stored with the trace.
    u_d_sd_deg : ndarray or None
        Pointwise posterior SD of ``u_d``, °, for a method that has a posterior.
    sample_posterior : callable or None
        ``sample_posterior(size, seed) -> (size, N)`` whole ``u_d`` traces drawn
        from their posterior given the recording, for a method that has one.
    """

    method: str
    model: str
    params: RollParams
    disturbance: Disturbance
    metrics: Mapping[str, Any]
    trace_settings: Mapping[str, Any] = field(default_factory=dict)
    u_d_sd_deg: FloatArray | None = None
    sample_posterior: Callable[[int, int], FloatArray] | None = None


#: ``method(context, models) -> fits``: one :class:`ModelFit` per model asked for.
MethodFunction = Callable[["Context", Sequence[str]], Sequence[ModelFit]]

#: Every identification method, by name.
METHODS: Registry[MethodFunction] = Registry("identification method")


@dataclass(frozen=True)
class MethodTraits:
    """What a registered identification method is (:func:`register_method`'s arguments).

    Attributes
    ----------
    models : tuple of str
        The damping models it can fit.
    default : bool
        Run without ``--method``.
    posterior : bool
        Its fits carry posterior draws of ``u_d``.
    database : bool
        Part of the default database's recipe.
    flight : bool
        It identifies flights, and only those.
    """

    models: tuple[str, ...] = MODEL_NAMES
    default: bool = False
    posterior: bool = False
    database: bool = False
    flight: bool = False


def traits(method: str) -> MethodTraits:
    """The traits of the method registered as ``method`` (``ValueError`` naming the known
    ones for another name)."""
    found: MethodTraits = METHODS.entry(method).info["traits"]
    return found


def register_method(
    name: str,
    method: MethodFunction | str,
    *,
    summary: str = "",
    default: bool = False,
    models: Sequence[str] = MODEL_NAMES,
    posterior: bool = False,
    database: bool | None = None,
    flight: bool = False,
    replace: bool = False,
) -> None:
    """Register an identification method.

    Parameters
    ----------
    name : str
        What users type (``--method NAME``, ``method=NAME``).
    method : callable or str
        ``method(context, models) -> [ModelFit, ...]``, or ``"module:function"``
        imported on first use.
    summary : str
        One line for ``--help``.
    default : bool
        Part of what ``rocketroll identify`` and ``rocketroll db add`` run
        without ``--method`` (and, unless ``database`` says otherwise, of the
        default database).
    models : sequence of str
        The damping models the method can fit.
    posterior : bool
        Its fits carry ``u_d_sd_deg`` and ``sample_posterior`` (posterior
        draws can be stored with its traces).
    database : bool, optional
        Part of the default database's recipe; default: ``default``.
    flight : bool
        It identifies flights (recordings with ``airspeed_mps``, format 1.1), and
        only those; the others identify the tunnel's constant airspeed.  With
        ``default``, it runs without ``--method`` on a flight.
    replace : bool
        Replace a method registered under ``name``.
    """
    for model in models:
        check_model(model)
    METHODS.register(
        name,
        method,
        summary=summary,
        replace=replace,
        traits=MethodTraits(
            models=tuple(models),
            default=default,
            posterior=posterior,
            database=(default and not flight) if database is None else database,
            flight=flight,
        ),
    )


def default_methods(recording: Recording | None = None) -> tuple[str, ...]:
    """The methods run when none is named, in registration order: for a flight
    recording (one whose airspeed changes, :attr:`Recording.is_flight`) the flight
    methods, else the tunnel's."""
    flight = recording is not None and recording.is_flight
    return tuple(
        e.name
        for e in METHODS.entries()
        if e.info["traits"].default and e.info["traits"].flight == flight
    )


def tunnel_methods(fitting: Sequence[str] = ()) -> tuple[str, ...]:
    """Every registered method that identifies the tunnel's recordings (not flights), and
    fits each damping model of ``fitting`` (any, where empty)."""
    return tuple(
        e.name
        for e in METHODS.entries()
        if not e.info["traits"].flight and set(fitting) <= set(e.info["traits"].models)
    )


def is_flight_method(method: str) -> bool:
    """Whether the method registered as ``method`` identifies flights."""
    return traits(method).flight


def has_posterior(method: str) -> bool:
    """Whether the method registered as ``method`` has a posterior to draw ``u_d`` from
    (False for a name that is not registered)."""
    return any(e.name == method and e.info["traits"].posterior for e in METHODS.entries())


def database_methods() -> tuple[str, ...]:
    """The methods of the default database's recipe, in registration order."""
    return tuple(e.name for e in METHODS.entries() if e.info["traits"].database)


class Context:
    """One recording being identified, shared by every method run on it.

    Parameters
    ----------
    recording : Recording
        The data.
    options : IdentifyOptions, optional
        Settings (the paper's defaults).
    paper : Identification, optional
        The paper's pipeline on this recording and these options, when the
        caller has it already.
    together : sequence of Recording, optional
        Other flights of the same rocket, fitted together with ``recording`` by
        the flight methods (each method's fit is ``recording``'s).
    """

    def __init__(
        self,
        recording: Recording,
        options: IdentifyOptions | None = None,
        paper: Identification | None = None,
        *,
        together: Sequence[Recording] = (),
    ) -> None:
        from identification.methods.pipeline import IdentifyOptions

        self.recording = recording
        self.together = tuple(together)
        self.options = IdentifyOptions() if options is None else options
        #: Each method's fits so far, by (method, models): :func:`fit` runs a method once.
        self.fits: dict[tuple[str, tuple[str, ...]], dict[str, ModelFit]] = {}
        if paper is not None:
            if paper.recording is not recording or paper.options != self.options:
                raise ValueError("the given identification is of another recording or options")
            self.__dict__["paper"] = paper

    @cached_property
    def paper(self) -> Identification:
        """The paper's pipeline (steps 1-9 and §3) on this recording."""
        from identification.methods.pipeline import identify

        return identify(self.recording, self.options)

    @cached_property
    def measurements(self) -> Measurements:
        """What every estimator starts from: steps 1 and 5, the smoothed velocity (§3.2)."""
        if "paper" in self.__dict__:
            return self.paper.measurements
        from identification.methods.pipeline import measurements

        return measurements(self.recording, self.options)

    def shared(self, key: str, make: Callable[[], Any]) -> Any:
        """What the methods run on this recording share (a search one of them makes and
        another takes, e.g. the sensors' latency), made once by ``make()`` under ``key``."""
        made: dict[str, Any] = self.__dict__.setdefault("_shared", {})
        if key not in made:
            made[key] = make()
        return made[key]

    def smoothed_over(self, window_s: float | None) -> Measurements:
        """:attr:`measurements` with the velocity smoothed over ``window_s`` instead of the
        options' window (None: the options'); made once per window."""
        return self.measured(window_s)

    def measured(
        self, window_s: float | None = None, latency_s: float | None = None
    ) -> Measurements:
        """:attr:`measurements` with the velocity smoothed over ``window_s`` (None: the
        options' window) and the fin delayed by a sensors' latency ``latency_s`` a method
        found (None: the stated one, if any); made once per pair."""
        if window_s is None and latency_s is None:
            return self.measurements
        made: dict[tuple[float | None, float | None], Measurements] = self.__dict__.setdefault(
            "_measured", {}
        )
        if (window_s, latency_s) not in made:
            from identification.methods.pipeline import measurements, with_latency

            options = self.options
            if window_s is not None:
                options = replace(options, smoothing_window_s=window_s)
            if latency_s is not None:
                options = with_latency(options, latency_s)
            made[window_s, latency_s] = measurements(self.recording, options)
        return made[window_s, latency_s]

    def measurements_of(self, found: ModelFit) -> Measurements:
        """The measurements ``found`` was fitted to: its own smoothing window, where its
        method chose one (``metrics["smoothing_window_s"]``), and the fin delayed by the
        sensors' latency, where its method found one (``metrics["sensor_latency"]``)."""
        latency = found.metrics.get("sensor_latency") or {}
        return self.measured(
            found.metrics.get("smoothing_window_s"),
            float(latency["estimate_s"]) if latency.get("admitted") else None,
        )

    def disturbance(self, params: RollParams, model: str) -> tuple[Disturbance, Resimulation]:
        """Steps 8-9 for any parameters: ``u_d`` by eq. 35-44, and its re-simulation (§3.5)."""
        from identification.methods.pipeline import recover_disturbance

        return recover_disturbance(self.measurements, params, model, self.options)


def fit(
    recording: Recording | Context,
    method: str = "paper",
    models: Sequence[str] = MODEL_NAMES,
    options: IdentifyOptions | None = None,
) -> dict[str, ModelFit]:
    """Identify ``recording`` with the method registered as ``method``.

    Parameters
    ----------
    recording : Recording or Context
        The data (a :class:`Context` to share work between methods).
    method : str
        A name of :data:`METHODS`: ``paper`` (default), ``output-error``, ...
    models : sequence of str
        Damping models to fit.
    options : IdentifyOptions, optional
        Settings, when ``recording`` is a recording.

    Returns
    -------
    dict
        ``{model: ModelFit}`` in the order of ``models``.

    Examples
    --------
    >>> from identification.instruments.bundled import load_bundled
    >>> from identification.methods.pipeline import IdentifyOptions
    >>> fits = fit(load_bundled("tunnel-paper-seed0"), "output-error", ["constant"],
    ...            IdentifyOptions(noise_runs=0))
    >>> round(fits["constant"].params.alpha, 2)
    0.67
    """
    context = recording if isinstance(recording, Context) else Context(recording, options)
    entry = METHODS.entry(method)
    rec = context.recording
    flight_method = traits(method).flight
    if rec.is_flight and not flight_method:
        from identification.methods.steps import IdentificationError

        assert rec.airspeed_mps is not None
        raise IdentificationError(
            f"recording {rec.name!r} is a flight (its airspeed_mps goes from "
            f"{float(np.min(rec.airspeed_mps)):.3g} to {float(np.max(rec.airspeed_mps)):.3g} "
            f"m/s): method {method!r} assumes the tunnel's one airspeed; use "
            + " or ".join(f"--method {m}" for m in default_methods(rec))
        )
    for one in (rec, *context.together) if flight_method else ():
        if one.airspeed_mps is None:
            from identification.methods.steps import IdentificationError

            raise IdentificationError(
                f"recording {one.name!r} has no airspeed_mps column: method {method!r} "
                "identifies flights (format 1.1); use "
                + " or ".join(f"--method {m}" for m in default_methods())
            )
    if context.together and not flight_method:
        from identification.methods.steps import IdentificationError

        raise IdentificationError(
            f"method {method!r} identifies one recording; other flights fitted together "
            f"({', '.join(repr(r.name) for r in context.together)}) are for the flight methods"
        )
    supported = traits(method).models
    for model in models:
        check_model(model)
        if model not in supported:
            raise ValueError(f"method {method!r} does not fit the {model!r} model")
    key = (method, tuple(models))
    if key in context.fits:  # fitted in this context already (identify, then store)
        return dict(context.fits[key])
    fits = {f.model: f for f in entry.load()(context, list(models))}
    missing = [m for m in models if m not in fits]
    if missing:
        raise RuntimeError(f"method {method!r} returned no fit for model(s) {missing}")
    if not flight_method:
        fits = {model: with_adequacy(f, context) for model, f in fits.items()}
    context.fits[key] = {m: fits[m] for m in models}
    return dict(context.fits[key])


def with_adequacy(found: ModelFit, context: Context) -> ModelFit:
    """``found`` with its adequacy (:mod:`identification.methods.adequacy`) in its metrics."""
    from identification.methods.adequacy import adequacy

    figures = adequacy(
        context.measurements_of(found),
        found.params,
        found.disturbance,
        found.metrics,
        method=found.method,
    )
    return replace(found, metrics={**found.metrics, "adequacy": figures.as_dict()})


def paper_method(context: Context, models: Sequence[str]) -> list[ModelFit]:
    """The paper's pipeline (:func:`~identification.methods.pipeline.identify`), a ModelFit per
    model.

    Its metrics: the steady-state fit (R², β), the piecewise-linear fit, the
    re-simulation errors and the per-step table; for the constant model also
    the damping fit and the noise study (§3.3), for the θ model the fit of
    eq. 48 and its outlier rule.
    """
    result = context.paper
    details = result.to_dict()
    common = {
        "n_steps": result.segments.n_steps,
        "sources": details["sources"],
        "steady_state_r2": result.steady.r_squared,
        "beta_dps": result.steady.beta_dps,
        "piecewise_rms_deg": result.piecewise.rms_deg,
    }
    fits = []
    for model in models:
        metrics: dict[str, Any] = {
            **common,
            **resimulation_metrics(result.resimulations[model]),
            "steps": details["steps"],
        }
        if model == "constant":
            metrics["damping_fit_rms_dps"] = result.damping.rms_dps
            metrics["noise_study"] = details["noise_study"]
        else:
            metrics["damping_vs_fin_r2"] = result.damping_vs_fin.r_squared
            metrics["damping_vs_fin"] = details["damping_vs_fin"]
        dist = result.disturbances[model]
        fits.append(
            ModelFit("paper", model, result.model(model), dist, metrics, trace_settings(dist))
        )
    return fits


def resimulation_metrics(r: Resimulation) -> dict[str, float]:
    """The re-simulation errors (§3.5) as stored metrics."""
    return {
        "resim_rate_mae_dps": r.rate_mae_dps,
        "resim_rate_sd_dps": r.rate_sd_dps,
        "resim_angle_mae_deg": r.angle_mae_deg,
        "resim_angle_sd_deg": r.angle_sd_deg,
    }


def trace_settings(dist: Disturbance) -> dict[str, Any]:
    """How a step-8 ``u_d`` was made (stored with its trace)."""
    return {"interval_s": dist.interval_s, "equations": "35-44"}


register_method(
    "paper",
    paper_method,
    summary="the paper's integral-based least squares (steps 1-6 of Fig. 9)",
    default=True,
)
register_method(
    "output-error",
    "identification.methods.baselines:output_error_method",
    summary="output-error nonlinear least squares on the simulated roll rate (the peer, §1)",
    default=True,
)
register_method(
    "ml",
    "identification.methods.ml:ml_method",
    summary="maximum likelihood: Kalman filter on the roll model with the turbulence as an "
    "AR state; its u_d is the posterior mean, and its posterior draws are what the "
    "environment replays by default",
    posterior=True,
    database=True,
)
register_method(
    "instrumental",
    "identification.methods.instrumental:instrumental_method",
    summary="instrumental variables on the model's sample map (the constant model): the "
    "excitation on top of a stated rate loop (identify --loop-gain, or the recording's "
    "loop.* lines) as the instrument, else the fin; consistent under the loop",
    models=("constant",),
)
register_method(
    "flight",
    "identification.methods.flight:flight_method",
    summary="a flight (a recording with airspeed_mps): maximum likelihood of a, α at a "
    "reference airspeed (--v-ref) with the airspeed scaling measured (fin torque ∝ ρV^n, "
    "damping ∝ ρV^m) and eq. 4-8 tested, the turbulence a field flown through; u_d from "
    "the Kalman smoother, its posterior draws from the simulation smoother",
    default=True,
    flight=True,
    posterior=True,
)
