"""The rocket in flight: the identified roll model carried along an ascent (the paper's §4).

A flight environment (``flight=`` of :class:`rollenv.config.RollConfig`) is the
tunnel's environment with three things changed, all decided here once per
configuration:

* **the episode** runs from the moment the airspeed first reaches the
  tunnel's ``V_ref`` (50 km/h: the rocket has left its launch rail and the
  fins have the authority the tunnel identified) to apogee, in whole control
  steps;
* **the rocket** changes every control step: gain ``α·V/V_ref`` and damping
  ``a(θ)·ρV/(ρ_ref·V_ref)`` (eq. 4-8; :func:`rocketroll_physics.scaling.roll_scales`),
  taken at the step's midpoint.  Both vanish as ``V → 0`` at apogee; they are
  held at :data:`MIN_SCALE` or above, where the rocket simply keeps rolling;
* **the turbulence** is flown: a tunnel trace time-compressed and scaled by
  :mod:`rocketroll_physics.flown`, sampled on the env's substep grid.

A flight stored in the database (``rocketroll db add`` of a flight log: its
rocket identified at a reference airspeed with its measured airspeed scaling)
is flown as **that rocket** (:func:`stored_flight_name`, ``flight="db:PATH#NAME"``):
its own V(t) and altitude, its gain and damping scaled by its own exponents
(:class:`rocketroll_physics.scaling.FlightReference`), and its own ``u_d`` -- the
identified one or its posterior draws, already in flight time -- replayed
(``flight_turbulence="recorded"``).

Documented assumptions: constant ``C_P``, ``C_δ`` and inertia (subsonic: the
default flight peaks at Mach 0.5, the paper's §4 warns of change past 0.8);
θ̄ (a geometric asymmetry) does not change with airspeed; ᾱ and β̄ of a(θ)
scale together, like ``a``.
"""

from __future__ import annotations

import functools
import math
import warnings
from dataclasses import dataclass

import numpy as np

from disturbances.bank import TraceBank
from disturbances.flight import flight_bank
from disturbances.rows import derived_row
from rocketroll_common.arrays import FloatArray, readonly_array
from rocketroll_physics.ascent import FlightProfile, flight_profile, recorded_profile
from rocketroll_physics.atmosphere import ISA_SEA_LEVEL_DENSITY_KGM3
from rocketroll_physics.flown import flow_amplitude, interval_means, tunnel_time
from rocketroll_physics.scaling import MACH_LIMIT, TUNNEL_AIRSPEED_MPS, FlightReference, roll_scales

__all__ = [
    "INFO_COLUMNS",
    "MIN_SCALE",
    "FlightSchedule",
    "flight_profile",
    "flight_schedule",
    "for_flight",
    "reflown",
    "stored_flight_name",
    "tunnel_frame",
    "turbulence_of",
]

#: What a flight env's ``info`` adds (:class:`rocketroll_physics.ascent.FlightState` fields).
INFO_COLUMNS = ("airspeed_mps", "altitude_m", "dynamic_pressure_pa", "mach")

#: The smallest gain and damping multiplier (near apogee the airflow, and with it the roll
#: model's coefficients, vanish; the kernel needs them positive).
MIN_SCALE = 1e-3


@dataclass(frozen=True, eq=False)
class FlightSchedule:
    """One flight on the environment's time grid.

    Attributes
    ----------
    profile : FlightProfile
        The ascent.
    start_s : float
        Profile time of the episode's start (the airspeed first reaches ``v_ref_mps``), s.
    steps : int
        Control steps to apogee.
    dt_s : float
        Control step, s.
    scales : ndarray, shape (steps, 2)
        Gain and damping multipliers per control step (:class:`rollenv.layout.Scale`).
    edges_s : ndarray, shape (steps·substeps + 1,)
        Episode time of the substep edges (the flown ``u_d`` samples), s.
    airspeed_edges_mps, altitude_edges_m : ndarray, shape (steps·substeps + 1,)
        Airspeed, m/s, and altitude above sea level, m, at those edges.
    at_steps : dict of str to ndarray, shape (steps + 1,)
        What the flight is at the start of each control step (and at its end):
        ``airspeed_mps``, ``altitude_m``, ``dynamic_pressure_pa``, ``mach``
        (the env's ``info``; precomputed, so a step reads them, not interpolates).
    v_ref_mps, rho_ref_kgm3 : float
        The tunnel's airspeed and density (where the model was identified, and where the
        episode starts).
    reference : FlightReference or None
        A stored flight's rocket's reference and scaling, which ``scales`` follow
        (None: the tunnel's rocket by eq. 4-8 from ``v_ref_mps``, ``rho_ref_kgm3``).
    recorded_on : FlightProfile or None
        Where a stored flight's rocket flies another ascent: the profile its ``u_d`` was
        recorded on (the recorded turbulence is flown anew by height:
        :func:`for_flight`); None on its own profile or a tunnel rocket's.
    airspeed_ratio : ndarray, shape (steps,)
        ``V/v_ref_mps`` at each control step's midpoint (at least :data:`MIN_SCALE`): how
        fast the flight flies through the turbulence's frozen field, which is stated at
        the tunnel's airspeed (:mod:`rocketroll_physics.flown`).  For the tunnel's rocket
        by eq. 4-8 it is the gain of ``scales``; a stored rocket's gain follows its own
        reference and exponents.
    """

    profile: FlightProfile
    start_s: float
    steps: int
    dt_s: float
    scales: FloatArray
    edges_s: FloatArray
    airspeed_edges_mps: FloatArray
    altitude_edges_m: FloatArray
    at_steps: dict[str, FloatArray]
    v_ref_mps: float
    rho_ref_kgm3: float
    reference: FlightReference | None = None
    recorded_on: FlightProfile | None = None
    airspeed_ratio: FloatArray | None = None

    @property
    def tunnel_gain(self) -> float:
        """The rocket's gain factor (of ``scales``) at the tunnel's airspeed."""
        if self.reference is None:
            return 1.0
        gain, _ = self.reference.scales(self.v_ref_mps, self.rho_ref_kgm3)
        return float(gain)

    @property
    def duration_s(self) -> float:
        """Episode length, s."""
        return self.steps * self.dt_s

    def step_times_s(self) -> FloatArray:
        """Profile time at the start of each control step, s."""
        return np.asarray(self.start_s + self.dt_s * np.arange(self.steps))

    def __repr__(self) -> str:
        gain = self.scales[:, 0]
        return (
            f"FlightSchedule({self.steps} steps of {self.dt_s:g} s from t={self.start_s:.2f} s, "
            f"gain {gain.min():.3g}..{gain.max():.3g}, {self.profile.source})"
        )


def flight_schedule(
    name: str,
    dt_s: float,
    substep_s: float,
    v_ref_mps: float = TUNNEL_AIRSPEED_MPS,
    rho_ref_kgm3: float = ISA_SEA_LEVEL_DENSITY_KGM3,
    model: str = "theta",
    profile: str | None = None,
) -> FlightSchedule:
    """The flight ``name`` (:func:`flight_profile`, or a stored flight's
    :func:`stored_flight_name`, whose ``model`` fit gives the rocket's scaling) on a grid
    of ``dt_s`` control steps of ``substep_s`` substeps; ``ValueError`` if it never
    reaches ``v_ref_mps`` or is shorter than one control step after that.  Cached per
    profile and grid.

    ``profile`` flies another ascent (a name of :func:`flight_profile`) instead: a stored
    flight's rocket on it, its recorded ``u_d`` flown anew (:func:`reflown`)."""
    if name.startswith(STORED_PREFIX):
        own, reference = stored_flight(name, model)
        if profile is None:
            return _schedule(own, dt_s, substep_s, v_ref_mps, rho_ref_kgm3, reference)
        other = flight_profile(profile)
        return _schedule(other, dt_s, substep_s, v_ref_mps, rho_ref_kgm3, reference, own)
    return _schedule(flight_profile(profile or name), dt_s, substep_s, v_ref_mps, rho_ref_kgm3)


#: How a stored flight is named as a profile: ``db:PATH#RECORDING``.
STORED_PREFIX = "db:"


def stored_flight_name(db_path: str, recording: str) -> str:
    """The ``flight`` of a configuration that flies the flight ``recording`` stored in the
    database at ``db_path`` as that rocket (its profile, scaling and ``u_d``)."""
    return f"{STORED_PREFIX}{db_path}#{recording}"


def stored_flight(name: str, model: str) -> tuple[FlightProfile, FlightReference]:
    """The profile of the stored flight ``name`` (:func:`stored_flight_name`: its logged
    airspeed and altitude, the site's elevation added back) and its ``model`` fit's
    reference and scaling.  Cached per file state.

    Raises
    ------
    ValueError
        If the name is not a stored flight's, the database cannot be opened, or holds no
        flight fit of ``model`` for the recording.
    """
    import os

    path, sep, recording = name.removeprefix(STORED_PREFIX).rpartition("#")
    if not (name.startswith(STORED_PREFIX) and sep and path and recording):
        raise ValueError(f"flight: {name!r} is not a stored flight (db:PATH#RECORDING)")
    try:
        stat = os.stat(path)
    except OSError as exc:
        raise ValueError(f"flight: {path}: {exc.strerror or 'cannot be read'}") from None
    return _stored(path, recording, model, stat.st_mtime_ns, stat.st_size)


@functools.lru_cache(maxsize=8)
def _stored(
    path: str, recording: str, model: str, mtime_ns: int, size: int
) -> tuple[FlightProfile, FlightReference]:
    del mtime_ns, size  # the cache key: a changed file is read again
    from disturbances.db import DisturbanceDB
    from identification.recordings.flight import site_elevation

    with DisturbanceDB(path, create=False) as db:
        fits = [
            row
            for row in db.identifications(recording=recording, model=model)
            if row.flight_reference is not None
        ]
        if not fits:
            raise ValueError(
                f"flight: {path} holds no flight fit of the {model} model for {recording!r} "
                f"(rocketroll db add FLIGHT.csv --db {path})"
            )
        reference = fits[-1].flight_reference
        assert reference is not None
        log = db.recording(fits[-1].recording_hash)
    if log.airspeed_mps is None or log.altitude_m is None:
        raise ValueError(f"flight: {recording!r} in {path} logs no airspeed and altitude")
    profile = recorded_profile(
        log.time_s,
        np.maximum(log.airspeed_mps, 0.0),
        log.altitude_m + site_elevation(log),
        f"stored flight {recording} ({path})",
    )
    return profile, reference


@functools.lru_cache(maxsize=16)
def _schedule(
    profile: FlightProfile,
    dt_s: float,
    substep_s: float,
    v_ref_mps: float,
    rho_ref_kgm3: float,
    reference: FlightReference | None = None,
    recorded_on: FlightProfile | None = None,
) -> FlightSchedule:
    if profile.max_mach > MACH_LIMIT:
        warnings.warn(
            f"flight: {profile.source} reaches Mach {profile.max_mach:.2f}; the roll model's "
            f"airspeed scaling is subsonic (above Mach {MACH_LIMIT:g} it does not hold), so "
            "the environment's rocket is not the real one there",
            UserWarning,
            stacklevel=3,
        )
    start, end = profile.window(v_ref_mps)
    steps = math.floor((end - start) / dt_s + 1e-9)
    if steps < 1:
        raise ValueError(f"flight: {profile.source} lasts less than one control step")
    middle = profile.at(start + dt_s * (np.arange(steps) + 0.5))
    if reference is None:
        gain, damping = roll_scales(
            middle.airspeed_mps, middle.density_kgm3, v_ref_mps, rho_ref_kgm3
        )
    else:
        gain, damping = reference.scales(middle.airspeed_mps, middle.density_kgm3)
    scales = np.maximum(np.column_stack([gain, damping]), MIN_SCALE)
    substeps = round(dt_s / substep_s)
    edges = substep_s * np.arange(steps * substeps + 1)
    along = profile.at(start + edges)
    at = profile.at(start + dt_s * np.arange(steps + 1))
    at_steps = {name: readonly_array(np.asarray(getattr(at, name))) for name in INFO_COLUMNS}
    return FlightSchedule(
        profile=profile,
        start_s=start,
        steps=steps,
        dt_s=dt_s,
        scales=readonly_array(scales),
        edges_s=readonly_array(edges),
        airspeed_edges_mps=readonly_array(np.asarray(along.airspeed_mps)),
        altitude_edges_m=readonly_array(np.asarray(along.altitude_m)),
        at_steps=at_steps,
        v_ref_mps=v_ref_mps,
        rho_ref_kgm3=rho_ref_kgm3,
        reference=reference,
        recorded_on=recorded_on,
        airspeed_ratio=readonly_array(
            np.maximum(np.asarray(middle.airspeed_mps) / v_ref_mps, MIN_SCALE)
        ),
    )


#: Dryden flights per split: each one episode of the roll gust, seeded by split and index.
DRYDEN_FLIGHTS = 256
#: The Dryden flights' seeds: the train and the test split never share a flight.
_DRYDEN_SEED = 20261124
_SPLIT_INDEX = {"train": 0, "test": 1}


def turbulence_of(bank: TraceBank) -> str | None:
    """``"tunnel"`` or ``"dryden"`` for a bank of flights (:func:`for_flight`), None for
    tunnel traces."""
    kinds = {t.settings.get("turbulence") for t in bank.traces}
    if kinds == {None}:
        return None
    if len(kinds) != 1:
        raise ValueError(f"{bank.description}: mixes flights and tunnel traces")
    return str(kinds.pop())


#: Banks of flights by (tunnel bank, schedule, steps, turbulence, severity, split).
_FLIGHTS: dict[tuple[object, ...], tuple[TraceBank, TraceBank]] = {}


def for_flight(
    bank: TraceBank,
    schedule: FlightSchedule,
    *,
    steps: int,
    substeps: int,
    turbulence: str = "tunnel",
    severity: str = "light",
    split: str = "train",
) -> TraceBank:
    """The flights an env replays: one trace per flight, ``steps`` control steps of
    ``substeps`` substeps, on ``bank``'s rockets.  Cached.

    ``turbulence="tunnel"``: ``bank``'s traces flown (:func:`disturbances.flight.flight_bank`).
    ``"recorded"``: a stored flight's own ``u_d`` traces (identified or posterior draws,
    in flight time), averaged onto the episode's substeps from its start; on another
    ascent (``schedule.recorded_on``), flown anew by height (:func:`reflown`).
    ``"dryden"``: :data:`DRYDEN_FLIGHTS` draws of the Dryden roll gust ``p_g``
    (:func:`rocketroll_physics.dryden.roll_gust`, ``severity``, seeded by ``split``) along the
    flight, the rockets taken in turn from ``bank``, as the equivalent fin angle
    ``u_d = p_g / (α₀·gain)``: the gust rolls the air the damping works against, ``a·(v -
    p_g)``, which is eq. 36 with ``α·u_d = p_g``.  A bank of flights of that turbulence is
    returned as it is.
    """
    if turbulence == "recorded":
        return _recorded(bank, schedule, steps * substeps + 1)
    made = turbulence_of(bank)
    if made == turbulence:
        return bank
    if made is not None:
        raise ValueError(f"{bank.description}: flights of {made} turbulence, not {turbulence}")
    key = (id(bank), id(schedule), steps, turbulence, severity, split)
    hit = _FLIGHTS.get(key)
    if hit is not None and hit[0] is bank:
        return hit[1]
    m = steps * substeps + 1
    if turbulence == "tunnel":
        result = flight_bank(
            bank,
            schedule.edges_s[:m],
            schedule.airspeed_edges_mps[:m],
            v_ref_mps=schedule.v_ref_mps,
            marks={"turbulence": "tunnel"},
        )
    elif turbulence == "dryden":
        result = _dryden(bank, schedule, m, substeps, severity, split)
    else:
        raise ValueError(f"turbulence must be 'tunnel' or 'dryden', not {turbulence!r}")
    if len(_FLIGHTS) >= 8:
        _FLIGHTS.clear()
    _FLIGHTS[key] = (bank, result)
    return result


def _recorded(bank: TraceBank, schedule: FlightSchedule, m: int) -> TraceBank:
    """A stored flight's traces on the episode's ``m`` substep edges from its start."""
    made = turbulence_of(bank)
    if made == "recorded":
        return bank
    h = float(schedule.edges_s[1] - schedule.edges_s[0])
    rows = []
    for source in bank.traces:
        if source.flight_reference is None or source.u_d_deg is None:
            raise ValueError(
                f"flight_turbulence='recorded' replays a stored flight's own u_d; "
                f"{bank.description} holds the tunnel's (trace {source.uid})"
            )
        if schedule.recorded_on is None:
            edges = schedule.start_s - source.t0_s + schedule.edges_s[:m]
            u = interval_means(source.u_d_deg, source.dt_s, edges)
        else:
            u = reflown(source.u_d_deg, source.t0_s, source.dt_s, schedule, m)
        rows.append(derived_row(source, u, h, "recorded", {"turbulence": "recorded"}))
    where = "as recorded in flight" if schedule.recorded_on is None else "flown anew by height"
    return TraceBank(rows, f"{bank.description}, {where}")


def tunnel_frame(bank: TraceBank, schedule: FlightSchedule) -> TraceBank:
    """A stored flight's ``u_d`` traces (in flight time, on the profile they were recorded
    on) in the tunnel's frame, where a turbulence model is stated before it is flown along
    a flight (:meth:`agents.observer.TurbulenceModel.flown`).

    The flown law turned around in time, as :func:`reflown` turns it around in height: a
    sample held over ``[t, t + Δt]`` of flight time covers tunnel time ``∫V/V_ref dt``
    (:func:`rocketroll_physics.flown.tunnel_time`) and its flow angle at the tunnel's
    scale is ``u_d·max(V, V_ref)/V_ref``; the result is averaged onto a uniform grid of
    the trace's own ``Δt``.
    """
    own = schedule.recorded_on or schedule.profile
    v_ref = schedule.v_ref_mps
    rows = []
    for source in bank.traces:
        if source.flight_reference is None or source.u_d_deg is None:
            raise ValueError(f"{bank.description}: trace {source.uid} is not a stored flight's u_d")
        u = np.asarray(source.u_d_deg, dtype=float)
        dt = source.dt_s
        edges = source.t0_s + dt * np.arange(u.size + 1)
        tau = tunnel_time(
            np.asarray(edges, dtype=np.float64), np.asarray(own.at(edges).airspeed_mps), v_ref
        )
        middle = np.asarray(own.at(edges[:-1] + 0.5 * dt).airspeed_mps)
        field = u / flow_amplitude(middle, v_ref)
        swept = np.concatenate([[0.0], np.cumsum(field * np.diff(tau))])
        grid = dt * np.arange(math.floor(tau[-1] / dt + 1e-9) + 1)
        means = np.diff(np.interp(grid, tau, swept)) / dt
        rows.append(derived_row(source, means, dt, "tunnel-frame", {"frame": "tunnel"}))
    return TraceBank(rows, f"{bank.description}, in the tunnel's frame")


def reflown(
    u_d_deg: FloatArray, t0_s: float, dt_s: float, schedule: FlightSchedule, m: int
) -> FloatArray:
    """A stored flight's ``u_d`` (from ``t0_s``, every ``dt_s``, on the profile
    ``schedule.recorded_on``) flown anew along ``schedule``'s other ascent: per interval of
    its first ``m`` substep edges.

    The law of :mod:`rocketroll_physics.flown` turned around: the recorded equivalent fin
    angle is a frozen gust field's flow angle, ``u_d = w(x)·V_ref/max(V, V_ref)`` at the
    height ``x`` above the pad (the distance a vertical flight has flown through it), so
    ``w`` is read off the recording by height and flown at the other ascent's heights and
    airspeeds (each interval's midpoint).

    Raises
    ------
    ValueError
        Where the other ascent's episode flies through heights the recording does not
        cover (its turbulence there is unknown).
    """
    own = schedule.recorded_on
    assert own is not None
    v_ref = schedule.v_ref_mps
    u = np.asarray(u_d_deg, dtype=float)
    there = own.at(t0_s + dt_s * (np.arange(u.size) + 0.5))
    heights = np.asarray(there.altitude_m) - float(own.altitude_m[0])
    field = u / flow_amplitude(there.airspeed_mps, v_ref)
    order = np.argsort(heights, kind="stable")  # the ascent: heights rise
    mid = 0.5 * (schedule.altitude_edges_m[1:m] + schedule.altitude_edges_m[: m - 1])
    flown = mid - float(schedule.profile.altitude_m[0])
    low, high = float(heights.min()), float(heights.max())
    if flown.min() < low - 1.0 or flown.max() > high + 1.0:
        raise ValueError(
            f"flight: the stored flight's u_d covers {low:.0f}-{high:.0f} m above its pad; "
            f"{schedule.profile.source} flies {flown.min():.0f}-{flown.max():.0f} m above its "
            "own, where that turbulence is unknown (fly an ascent within those heights, or "
            "cut the episode with episode_s)"
        )
    speed = 0.5 * (schedule.airspeed_edges_mps[1:m] + schedule.airspeed_edges_mps[: m - 1])
    return np.asarray(np.interp(flown, heights[order], field[order]) * flow_amplitude(speed, v_ref))


def _dryden(
    bank: TraceBank, schedule: FlightSchedule, m: int, substeps: int, severity: str, split: str
) -> TraceBank:
    from rocketroll_physics.dryden import roll_gust

    height = schedule.altitude_edges_m[:m] - schedule.profile.altitude_m[0]
    rng = np.random.default_rng([_DRYDEN_SEED, _SPLIT_INDEX[split]])
    gust = roll_gust(
        schedule.edges_s[:m],
        schedule.airspeed_edges_mps[:m],
        np.maximum(height, 0.0),
        severity=severity,  # type: ignore[arg-type]
        rng=rng,
        size=DRYDEN_FLIGHTS,
    )
    gain = np.repeat(schedule.scales[: (m - 1) // substeps, 0], substeps)
    h = float(schedule.edges_s[1] - schedule.edges_s[0])
    rows = []
    for k in range(DRYDEN_FLIGHTS):
        source = bank.traces[k % len(bank)]
        u = gust[k] / (source.rocket().alpha * gain)
        settings = {
            "turbulence": "dryden",
            "severity": severity,
            "flown_from": source.uid,
            "flight": k,
            "split_seed": [_DRYDEN_SEED, _SPLIT_INDEX[split]],
        }
        rows.append(derived_row(source, u, h, f"dryden-{severity}-{k}", settings))
    return TraceBank(rows, f"{bank.description}, Dryden {severity} flights")
