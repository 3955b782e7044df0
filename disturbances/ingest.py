"""Identifying recordings and making surrogates into a database: the service above the store.

:class:`~disturbances.db.DisturbanceDB` only stores rows.  This module makes
them and hands them over, one transaction per call:

* :func:`add_recording` -- identify a recording by the identification methods
  asked for (:mod:`identification.methods`; by default the registered default
  ones: the paper's and the output-error peer), each for every damping model
  it fits, and store the recording, one identification row per method and
  model and its ``u_d`` trace, plus surrogates;
* :func:`add_identification` -- the same from the paper's pipeline already
  run (``rocketroll identify --db``);
* :func:`add_surrogates` -- surrogates of a stored trace.

With ``holdout`` :func:`add_recording` stores one run as two recordings of its
name (:func:`holdout_rows`): the part before the last ``holdout`` of it, in the
train split, identified on its own -- what a controller may be designed and
tuned on -- and the whole run in the test split, identified on all of it (the
best model of the rocket, the evaluation's judge), with its traces cut to the
held-out end: what an evaluation replays.  ``--recording NAME`` then designs on
the first and evaluates on the second.

A method with a posterior (``ml``) can also store ``posterior`` draws of each
of its traces (``kind="posterior"``): whole ``u_d`` traces from ``p(u_d |
recording)``, each with its seed, the identified (posterior-mean) trace as
its source and the same parameters.  They are drawn when the recording is
identified, from that fit.

Every method's trace is recovered and re-simulated the same way (steps 8-9,
:meth:`identification.methods.Context.disturbance`) unless the method makes
its own, so traces and metrics of all methods compare like for like.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping, Sequence
from typing import Any, Literal

import numpy as np

from disturbances.db import DatabaseError, StoreResult, now, package_version
from disturbances.rows import (
    ACCEPTED_UNRELIABLE,
    POSTERIOR_KIND,
    SURROGATE_KINDS,
    IdentificationRow,
    RecordingRow,
    TraceRow,
    checksum,
    content_hash,
    identified_uid,
    posterior_uid,
    surrogate_uid,
)
from disturbances.stores import Store, store_rows
from identification.methods import (
    METHODS,
    Context,
    ModelFit,
    default_methods,
    fit,
    has_posterior,
    traits,
)
from identification.methods.pipeline import Identification, IdentifyOptions, fitted_rig
from identification.methods.statistics import trace_statistics
from identification.model import Rig
from identification.recordings.recording import Recording
from rocketroll_common.arrays import FloatArray
from rocketroll_common.errors import UsageError
from rocketroll_physics.scaling import FlightReference

__all__ = [
    "HOLDOUT_RANGE",
    "add_identification",
    "add_recording",
    "add_surrogates",
    "holdout_rows",
    "identification_rows",
    "posterior_rows",
    "split_parts",
    "surrogate_rows",
    "trace_summary",
]


def trace_summary(u_d_deg: np.ndarray) -> dict[str, Any]:
    """Mean, SD, 90 % interval and normality p-value of a trace (§3.4)."""
    st = trace_statistics(u_d_deg)
    return {
        "mean_deg": st.mean_deg,
        "sd_deg": st.sd_deg,
        "q05_deg": st.q05_deg,
        "q95_deg": st.q95_deg,
        "normality_p": st.lilliefors_p,
    }


def _trace_row(
    recording: RecordingRow, fitted: ModelFit, created_at: str, version: str, rig: Rig
) -> TraceRow:
    dist = fitted.disturbance
    u = np.asarray(dist.u_d_deg, dtype=float)
    return TraceRow(
        uid=identified_uid(recording.content_hash, fitted.method, fitted.model),
        recording_hash=recording.content_hash,
        method=fitted.method,
        model=fitted.model,
        kind="identified",
        source_uid=None,
        seed=None,
        settings=dict(fitted.trace_settings),
        dt_s=dist.interval_s,
        t0_s=float(dist.start_s[0]),
        checksum=checksum(u),
        statistics=trace_summary(u),
        validation=None,
        created_at=created_at,
        u_d_deg=u,
        params=fitted.params,
        recording=recording.name,
        source=recording.source,
        split=recording.split,
        package_version=version,
        flight_reference=FlightReference.from_metrics(fitted.metrics),
        rig=rig,
    )


def posterior_rows(
    identified: TraceRow, fitted: ModelFit, count: int, seed: int = 0
) -> list[TraceRow]:
    """``count`` posterior draws of ``u_d`` that go with the identified trace of ``fitted``.

    Draw ``k`` has seed ``seed + k`` and is ``fitted.sample_posterior(1, seed + k)``:
    the same fit and seed always give the same draw.
    """
    if count < 0:
        raise ValueError(f"count must be non-negative, got {count}")
    sample = fitted.sample_posterior
    if count and sample is None:
        raise ValueError(f"method {fitted.method!r} has no posterior to draw from")
    rows = []
    for k in range(count):
        assert sample is not None
        u: FloatArray = np.asarray(sample(1, seed + k)[0], dtype=np.float64)
        rows.append(
            dataclasses.replace(
                identified,
                uid=posterior_uid(identified.uid, seed + k),
                kind=POSTERIOR_KIND,
                source_uid=identified.uid,
                seed=seed + k,
                settings={
                    **identified.settings,
                    "estimate": "posterior draw (simulation smoother, Durbin & Koopman 2002)",
                },
                checksum=checksum(u),
                statistics=trace_summary(u),
                u_d_deg=u,
                id=None,
            )
        )
    return rows


#: The shares of a run that may be held out for evaluation (the design keeps the rest).
HOLDOUT_RANGE = (0.1, 0.8)


def holdout_rows(
    context: Context,
    fraction: float,
    methods: Sequence[str] | None = None,
    *,
    posterior: int = 0,
    posterior_seed: int = 0,
) -> tuple[list[RecordingRow], list[IdentificationRow], list[TraceRow]]:
    """Rows of one run split in time for an honest evaluation (module docstring): its part
    before the last ``fraction`` (train split, identified on that part only) and the whole
    run (test split, identified on all of it) with its traces -- identified and posterior
    draws -- cut to the last ``fraction``.  Both keep the run's name; the parts' metadata
    say which they are (``part``: ``design`` / ``held-out``, ``part.to_s`` /
    ``part.from_s``)."""
    low, high = HOLDOUT_RANGE
    if not low <= fraction <= high:
        raise ValueError(f"holdout must be in [{low:g}, {high:g}], got {fraction!r}")
    rec = context.recording
    t = np.asarray(rec.time_s, dtype=float)
    cut = float(t[int(np.searchsorted(t, t[-1] - fraction * (t[-1] - t[0])))])
    design = rec.part(float(t[0]), cut, split="train", part="design", **{"part.to_s": f"{cut:g}"})
    judged = rec.part(
        float(t[0]), math.inf, split="test", part="held-out", **{"part.from_s": f"{cut:g}"}
    )
    recordings, identifications, traces = [], [], []
    for part in (design, judged):
        recording, idents, rows = identification_rows(
            Context(part, context.options),
            methods,
            posterior=posterior,
            posterior_seed=posterior_seed,
        )
        if part is judged:
            rows = [_from(row, cut) for row in rows]
        recordings.append(recording)
        identifications += idents
        traces += rows
    return recordings, identifications, traces


def split_parts(db: Store, name: str) -> list[RecordingRow]:
    """The parts of the run ``name`` stored split for a held-out evaluation
    (:func:`holdout_rows`; none where it is not)."""
    return [r for r in db.recordings() if r.name == name and "part" in r.metadata]


def _check_not_split(db: Store, recording: Recording, methods: Sequence[str]) -> None:
    """Refuse (:class:`DatabaseError`) to add ``methods``' fits of ``recording`` where a run
    of its name is stored split for a held-out evaluation (:func:`holdout_rows`), unless
    it is that run with every one of those methods already: they would be whole traces,
    replayed beside the held-out ones."""
    if not split_parts(db, recording.name):
        return
    recording_hash = content_hash(recording.columns())
    if db.has_recording(recording_hash) and all(
        db.has_identification(recording_hash, m, model)
        for m in methods
        for model in traits(m).models
    ):
        return  # nothing new: "already stored"
    raise DatabaseError(
        f"{db.path}: {recording.name} is stored split for a held-out evaluation (db add "
        "--holdout); a method or run added to it here would be replayed whole: split it "
        f"again with --holdout and --method {' --method '.join(methods)} into a new database "
        "(or give the run another name: rocketroll import-csv --name)"
    )


def _check_new_run(db: Store, recording: Recording) -> None:
    """Refuse (:class:`DatabaseError`) to split a run whose samples or name the database
    holds already: its stored traces (whole, in whichever split) would stay beside the
    held-out ones and be replayed with them."""
    whole = content_hash(recording.columns())
    named = [r for r in db.recordings() if r.name == recording.name]
    if db.has_recording(whole) or named:
        what = "this run's samples" if db.has_recording(whole) else "a recording of that name"
        raise DatabaseError(
            f"{db.path}: holds {what} ({recording.name}) already; a run is split for a "
            "held-out evaluation once, into a database without it (or give it another "
            "name: rocketroll import-csv --name)"
        )


def _from(row: TraceRow, start_s: float) -> TraceRow:
    """``row``'s trace from the first interval that starts at or after ``start_s``."""
    assert row.u_d_deg is not None
    skip = max(0, math.ceil((start_s - row.t0_s) / row.dt_s - 1e-9))
    u = np.asarray(row.u_d_deg[skip:], dtype=np.float64)
    if u.size < 2:
        from identification.methods.steps import IdentificationError

        raise IdentificationError(
            f"{row.recording}: its {row.method} trace holds less than two intervals after "
            f"{start_s:g} s; hold out a larger share"
        )
    return dataclasses.replace(
        row,
        t0_s=row.t0_s + skip * row.dt_s,
        u_d_deg=u,
        n_samples=u.size,
        checksum=checksum(u),
        statistics=trace_summary(u),
        settings={**row.settings, "held_out_from_s": start_s},
    )


def _check_posterior(methods: Sequence[str], posterior: int) -> None:
    if posterior and not any(has_posterior(m) for m in methods):
        with_one = [name for name in METHODS.names() if has_posterior(name)]
        raise ValueError(
            f"posterior draws need a method with a posterior ({', '.join(with_one) or 'none'}"
            f" registered); none of {', '.join(methods)} has one"
        )


def _methods(methods: Sequence[str] | None, recording: Recording | None = None) -> tuple[str, ...]:
    """``methods``, or the default ones for ``recording`` (a flight's are the flight's)."""
    chosen = default_methods(recording) if methods is None else tuple(methods)
    if not chosen:
        raise ValueError("give at least one identification method")
    for method in chosen:
        METHODS.check(method)
    if len(set(chosen)) < len(chosen):
        raise ValueError(f"a method is named twice in {list(chosen)}")
    return chosen


def identification_rows(
    context: Context,
    methods: Sequence[str] | None = None,
    *,
    posterior: int = 0,
    posterior_seed: int = 0,
) -> tuple[RecordingRow, list[IdentificationRow], list[TraceRow]]:
    """Rows for a recording, its identifications by ``methods`` and their traces.

    Parameters
    ----------
    context : Context
        The recording and the identification options.
    methods : sequence of str, optional
        Registered identification methods (default: the default ones); each
        fits every damping model it supports.
    posterior : int
        Posterior draws per trace of each method that has a posterior.
    posterior_seed : int
        Seed of the first draw (the next ones count up).
    """
    chosen = _methods(methods, context.recording)
    _check_posterior(chosen, posterior)
    stamp = now()
    version = package_version()
    recording = RecordingRow.of(context.recording, added_at=stamp)
    options = {k: v for k, v in dataclasses.asdict(context.options).items() if k != "progress"}
    identifications: list[IdentificationRow] = []
    traces: list[TraceRow] = []
    rig = context.recording.rig_with(context.options.rig)
    for method in chosen:
        for model, fitted in fit(context, method, traits(method).models).items():
            identifications.append(
                IdentificationRow(
                    recording.content_hash,
                    method,
                    model,
                    fitted.params,
                    fitted.metrics,
                    options,
                    version,
                    stamp,
                )
            )
            trace = _trace_row(recording, fitted, stamp, version, fitted_rig(rig, fitted.metrics))
            traces.append(trace)
            if fitted.sample_posterior is not None:
                traces += posterior_rows(trace, fitted, posterior, posterior_seed)
    return recording, identifications, traces


def _surrogate_method(methods: Sequence[str], surrogate_method: str | None) -> str:
    if surrogate_method is not None:
        return METHODS.check(surrogate_method)
    return "paper" if "paper" in methods else methods[0]


def _add_holdout(
    db: Store,
    context: Context,
    holdout: float,
    chosen: Sequence[str],
    posterior: int,
    posterior_seed: int,
    unreliable: Literal["store", "refuse", "accept"],
) -> StoreResult:
    """:func:`add_recording` of a run split for a held-out evaluation."""
    _check_new_run(db, context.recording)
    db.check_version(writing=True)
    recordings, identifications, traces = holdout_rows(
        context, holdout, chosen, posterior=posterior, posterior_seed=posterior_seed
    )
    judged = _judged(db, recordings, identifications, unreliable)
    return store_rows(db, recordings, judged, traces)


def add_recording(
    db: Store,
    recording: Recording,
    options: IdentifyOptions | None = None,
    *,
    methods: Sequence[str] | None = None,
    surrogates: int = 0,
    surrogate_kinds: Sequence[str] = ("iaaft",),
    surrogate_seed: int = 0,
    surrogate_method: str | None = None,
    posterior: int = 0,
    posterior_seed: int = 0,
    holdout: float = 0.0,
    context: Context | None = None,
    unreliable: Literal["store", "refuse", "accept"] = "store",
) -> StoreResult:
    """Identify a recording and store it with all its results, in one transaction.

    Each method in ``methods`` gives, for every model it fits, its parameters,
    fit metrics and ``u_d`` trace.  ``surrogates`` surrogate traces of each
    kind in ``surrogate_kinds`` are made from each trace of
    ``surrogate_method`` (the paper's, when it runs).  Nothing is written
    unless all of it succeeds.  A recording whose samples are already stored
    is recognised (``StoreResult.recordings == 0``): it is not stored twice,
    and identified again only by the methods it lacks.

    Parameters
    ----------
    db : Store
        Where to store (:class:`~disturbances.db.DisturbanceDB` or another back end).
    recording : Recording
        Any recording the pipeline accepts; a flight is stored with its flight
        method's fits (their reference airspeed and measured scaling, and ``u_d``
        in flight: the tunnel's environments do not replay it, the flight
        environment flies that rocket with it).
    options : IdentifyOptions, optional
        Identification settings (the paper's by default).
    methods : sequence of str, optional
        Registered identification methods; default: the default ones.
    surrogates : int
        Surrogates per kind and per trace of ``surrogate_method``.
    surrogate_kinds : sequence of str
        ``iaaft`` and/or ``ar``.
    surrogate_seed : int
        Seed of the first surrogate (the next ones count up).
    surrogate_method : str, optional
        Whose traces the surrogates are made from.
    posterior : int
        Posterior draws per trace of each method with a posterior (``ml``),
        made from this identification (a recording already identified by the
        method gets none).
    posterior_seed : int
        Seed of the first draw (the next ones count up).
    holdout : float
        0 (default): the recording as one.  Else the share of it at its end held out
        for evaluation (:func:`holdout_rows`: a design part and the held-out one, in
        :data:`HOLDOUT_RANGE`); no surrogates then.
    context : Context, optional
        Where ``recording`` was identified already with ``options`` (``rocketroll
        identify --db``): its methods' fits are stored, not made again.
    unreliable : {"store", "refuse", "accept"}
        What becomes of a recording every fit of which is judged unreliable (its stored
        ones too): ``"store"`` it as any other, ``"refuse"`` it (a ``UsageError`` that
        names the verdict's reasons and the override; nothing is stored), or ``"accept"``
        it, its new identifications marked (:data:`~disturbances.rows.ACCEPTED_UNRELIABLE`):
        ``rocketroll db add`` without and with ``--accept-unreliable``.
    """
    if unreliable not in ("store", "refuse", "accept"):
        raise ValueError(f"unreliable must be 'store', 'refuse' or 'accept', not {unreliable!r}")
    if context is not None and (context.recording is not recording or context.options != options):
        raise ValueError("context: of another recording or other options")
    chosen = _methods(methods, recording)
    _check_posterior(chosen, posterior)
    source_method = _surrogate_method(chosen, surrogate_method)
    if holdout:
        if surrogates:
            raise ValueError("a run split for a held-out evaluation gets no surrogates")
        return _add_holdout(
            db, Context(recording, options), holdout, chosen, posterior, posterior_seed, unreliable
        )
    if surrogates:
        _check_surrogate_length(recording, options or IdentifyOptions())
    recording_hash = content_hash(recording.columns())
    missing = [
        m
        for m in chosen
        if not all(db.has_identification(recording_hash, m, model) for model in traits(m).models)
    ]
    _check_not_split(db, recording, missing or chosen)
    if db.has_recording(recording_hash) and not missing:
        stored_id = db.recording_row(recording_hash).id
        if surrogates == 0:
            return StoreResult(stored_id, 0, 0, 0, 1, ())
        # Everything identified already: only the surrogates asked for are new.
        db.check_version(writing=True)
        made: list[TraceRow] = []
        for model in traits(source_method).models:
            source = db.trace(identified_uid(recording_hash, source_method, model))
            made += surrogate_rows(source, surrogate_kinds, surrogates, surrogate_seed)
        stored = store_rows(db, traces=made)
        return dataclasses.replace(stored, recording_id=stored_id, skipped=stored.skipped + 1)
    return _store(
        db,
        context or Context(recording, options),
        missing,
        surrogates=surrogates,
        surrogate_kinds=surrogate_kinds,
        surrogate_seed=surrogate_seed,
        surrogate_method=source_method,
        posterior=posterior,
        posterior_seed=posterior_seed,
        unreliable=unreliable,
    )


def _judged(
    db: Store,
    recordings: Sequence[RecordingRow],
    identifications: list[IdentificationRow],
    unreliable: str,
) -> list[IdentificationRow]:
    """The ``identifications`` (of ``recordings``) to store, where every fit of a recording
    among them (with those the database holds of it) is judged unreliable: refused
    (``UsageError``) or marked (:data:`~disturbances.rows.ACCEPTED_UNRELIABLE`) as
    ``unreliable`` says (:func:`add_recording`); as they are otherwise."""
    if unreliable == "store":
        return identifications
    judged = []
    for recording in recordings:
        recording_hash = recording.content_hash
        new = [i for i in identifications if i.recording_hash == recording_hash]
        stored = (
            db.identifications(recording_hash=recording_hash)
            if db.has_recording(recording_hash)
            else []
        )
        if not new or any(i.verdict != "unreliable" for i in (*new, *stored)):
            continue
        if unreliable == "refuse":
            fits: dict[str, list[str]] = {}
            for i in new:
                fits.setdefault(_first_reason(i), []).append(f"{i.method} {i.model}")
            reasons = "; ".join(f"{', '.join(by)}: {reason}" for reason, by in fits.items())
            raise UsageError(
                f"{recording.name}: every fit of it is judged unreliable ({reasons}); not "
                "stored: give --accept-unreliable to store it anyway, marked (the evaluations "
                "that replay it say so)"
            )
        judged.append(recording_hash)
    return [
        dataclasses.replace(i, metrics={**i.metrics, ACCEPTED_UNRELIABLE: True})
        if i.recording_hash in judged
        else i
        for i in identifications
    ]


def _first_reason(identification: IdentificationRow) -> str:
    """The first reason of an identification's adequacy verdict (the unreliable ones come
    first)."""
    figures = identification.metrics.get("adequacy")
    reasons = figures.get("reasons") if isinstance(figures, Mapping) else None
    return str(reasons[0]) if reasons else "no reason given"


def _check_surrogate_length(recording: Recording, options: IdentifyOptions) -> None:
    """Refuse, before any work, surrogates of a recording too short to check them."""
    from disturbances.surrogate import checked_min_samples

    needed = checked_min_samples()
    have = int(recording.duration_s / options.ud_interval_s)
    if have < needed:
        raise UsageError(
            f"{recording.name}: its u_d traces would hold {have} samples of "
            f"{options.ud_interval_s:g} s ({recording.duration_s:g} s), and a checked surrogate "
            f"needs {needed} ({needed * options.ud_interval_s:g} s): add it without surrogates "
            "(--surrogates 0) or record longer"
        )


def add_identification(
    db: Store,
    result: Identification,
    *,
    methods: Sequence[str] | None = None,
    surrogates: int = 0,
    surrogate_kinds: Sequence[str] = ("iaaft",),
    surrogate_seed: int = 0,
    surrogate_method: str | None = None,
    context: Context | None = None,
) -> StoreResult:
    """:func:`add_recording` for a recording the paper's pipeline has just identified.

    The pipeline's result is reused for ``method="paper"``; other methods run
    on the same measurements (their fits in ``context``, where it holds them, are
    reused too).
    """
    chosen = _methods(methods, result.recording)
    _check_not_split(db, result.recording, chosen)
    if context is not None and context.paper is not result:
        raise ValueError("context: of another identification")
    return _store(
        db,
        context or Context(result.recording, result.options, paper=result),
        chosen,
        surrogates=surrogates,
        surrogate_kinds=surrogate_kinds,
        surrogate_seed=surrogate_seed,
        surrogate_method=_surrogate_method(chosen, surrogate_method),
    )


def _store(
    db: Store,
    context: Context,
    methods: Sequence[str],
    *,
    surrogates: int,
    surrogate_kinds: Sequence[str],
    surrogate_seed: int,
    surrogate_method: str,
    posterior: int = 0,
    posterior_seed: int = 0,
    unreliable: str = "store",
) -> StoreResult:
    db.check_version(writing=True)
    recording, identifications, traces = identification_rows(
        context, methods, posterior=posterior, posterior_seed=posterior_seed
    )
    identifications = _judged(db, [recording], identifications, unreliable)
    if db.has_recording(recording.content_hash):
        # Partly stored already: new identifications must be made like the stored
        # ones, and surrogates come from the stored traces, never from new twins.
        stored_options = {
            _options_key(i.options)
            for i in db.identifications(recording_hash=recording.content_hash)
        }
        if stored_options and stored_options != {_options_key(identifications[0].options)}:
            raise DatabaseError(
                f"{db.path}: recording {recording.name} is stored with other identification "
                "options; add it to a new database to identify it differently"
            )
    made: list[TraceRow] = []
    if surrogates:
        sources = [t for t in traces if t.method == surrogate_method and t.kind == "identified"]
        if not sources:
            for model in traits(surrogate_method).models:
                uid = identified_uid(recording.content_hash, surrogate_method, model)
                if db.has_trace(uid):
                    sources.append(db.trace(uid))
        for trace in sources:
            source = db.trace(trace.uid) if db.has_trace(trace.uid) else trace
            made += surrogate_rows(source, surrogate_kinds, surrogates, surrogate_seed)
    return store_rows(db, [recording], identifications, [*traces, *made])


def _options_key(options: Any) -> str:
    """Options as compared: a setting an older version did not store counts as its
    default (a database written before it still takes new methods)."""
    defaults = {k: v for k, v in dataclasses.asdict(IdentifyOptions()).items() if k != "progress"}
    return json.dumps({**defaults, **dict(options)}, sort_keys=True)


def add_surrogates(
    db: Store, uid: str, kind: str = "iaaft", count: int = 1, seed: int = 0
) -> StoreResult:
    """Make ``count`` surrogates of a stored trace and store them (one transaction)."""
    if kind not in SURROGATE_KINDS:
        raise ValueError(f"kind must be one of {', '.join(SURROGATE_KINDS)}, not {kind!r}")
    source = db.trace(uid)
    if source.kind != "identified":
        raise DatabaseError(f"{db.path}: trace {uid} is itself a surrogate; use its source")
    db.check_version(writing=True)
    return store_rows(db, traces=surrogate_rows(source, (kind,), count, seed))


def surrogate_rows(
    source: TraceRow, kinds: Sequence[str], count: int, seed: int = 0
) -> list[TraceRow]:
    """``count`` surrogates of each kind in ``kinds`` made from ``source``.

    Surrogate ``k`` has seed ``seed + k``; its generator is seeded with that
    seed and the source's checksum, so the same source and seed always give
    the same surrogate and different sources give independent ones.  Each
    is checked against its source (two-sample KS of the marginals, Welch
    PSD log-distance); the check is stored with it.
    """
    from disturbances.surrogate import check_surrogate, make_surrogate

    if count < 0:
        raise ValueError(f"count must be non-negative, got {count}")
    unknown = [k for k in kinds if k not in SURROGATE_KINDS]
    if unknown:
        raise ValueError(f"unknown surrogate kind(s) {unknown}; use {', '.join(SURROGATE_KINDS)}")
    samples = source.samples()
    rows: list[TraceRow] = []
    stamp = now()
    entropy = int(source.checksum[:16], 16)
    for kind in kinds:
        for k in range(count):
            s = seed + k
            rng = np.random.default_rng([s, entropy])
            made = make_surrogate(samples, kind, rng)
            u = np.asarray(made.u_d_deg, dtype=float)
            check = check_surrogate(samples, u, source.dt_s)
            rows.append(
                dataclasses.replace(
                    source,
                    uid=surrogate_uid(source.uid, kind, s),
                    kind=kind,
                    source_uid=source.uid,
                    seed=s,
                    settings=dict(made.settings),
                    checksum=checksum(u),
                    statistics=trace_summary(u),
                    validation=check.to_dict(),
                    created_at=stamp,
                    u_d_deg=u,
                    id=None,
                )
            )
    return rows
