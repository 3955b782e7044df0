"""What the database holds, as plain frozen rows (no SQL here).

The same three row types carry data into the database (:mod:`disturbances.ingest`
makes them from an identification), out of it (listings, :meth:`DisturbanceDB.dump`)
and through export and import (:mod:`disturbances.exchange`), so there is one
description of a stored recording, identification and trace.  Read from a
database a row also carries its row ``id`` and what its joins give (a trace's
recording name, split and parameters); a listing leaves the samples out
(``samples``/``u_d_deg`` is None) and :meth:`DisturbanceDB.trace` reads them,
checked against their checksum.

Identity is by content, never by row number:

* a recording by :func:`content_hash` of its samples (the same samples added
  twice are one recording, whatever the file or name they came in);
* an identification by ``(recording hash, method, model)``;
* a trace by its ``uid``: ``<hash[:12]>-<method>-<model>`` for an identified
  trace, ``<source uid>-<surrogate method>-<seed>`` for a surrogate and
  ``<source uid>-posterior-<seed>`` for a posterior draw.

The train/test split belongs to the recording: its ``split`` metadata line
when it has one (a user holding out chosen runs), else a function of its
content hash (:func:`split_of`).  Either way it is deterministic, does not
move when the database grows, and every trace of a recording -- both models,
both methods and all surrogates -- falls on the same side: evaluation never
sees a disturbance that training saw in another form.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from identification.methods.adequacy import VERDICTS
from identification.model import MODEL_NAMES, Rig, RollParams, check_model
from identification.recordings.recording import SOURCES, Recording
from rocketroll_common.arrays import FloatArray, readonly_array
from rocketroll_common.errors import RocketrollError
from rocketroll_physics.scaling import FlightReference

__all__ = [
    "ACCEPTED_UNRELIABLE",
    "KINDS",
    "NAMES",
    "POSTERIOR_KIND",
    "SPLITS",
    "SURROGATE_KINDS",
    "TEST_FRACTION",
    "IdentificationRow",
    "RecordingRow",
    "TraceRow",
    "checksum",
    "content_hash",
    "derived_row",
    "identified_uid",
    "json_safe",
    "params_from_columns",
    "plain_statistics",
    "posterior_uid",
    "rig_from_json",
    "split_of",
    "surrogate_uid",
]

#: Surrogate generators of :mod:`disturbances.surrogate`.
SURROGATE_KINDS = ("iaaft", "ar")
#: A draw of ``u_d`` from its posterior given the recording (a method with a posterior, ``ml``).
POSTERIOR_KIND = "posterior"
#: A trace is identified from a recording (for a method with a posterior: its mean), a
#: surrogate of another trace, or a posterior draw that goes with an identified trace.
KINDS = ("identified", *SURROGATE_KINDS, POSTERIOR_KIND)
SPLITS = ("train", "test")
#: The values a stored name can take, by the column the store filters on.  A method
#: name is any: which are registered is the domain's to say (:mod:`disturbances.stores`).
NAMES: Mapping[str, tuple[str, ...]] = MappingProxyType(
    {
        "split": SPLITS,
        "model": MODEL_NAMES,
        "kind": (*KINDS, "surrogate"),
        "source": SOURCES,
        "verdict": VERDICTS,
    }
)
#: Share of recordings (by hash) that go to the test split.
TEST_FRACTION = 0.25
#: The metric (``True``) of an identification stored although every fit of its recording was
#: judged unreliable (:mod:`identification.methods.adequacy`), because the user said so:
#: ``rocketroll db add --accept-unreliable``; the evaluations that replay it say so under
#: their tables.
ACCEPTED_UNRELIABLE = "accepted_unreliable"
_SPLIT_SALT = b"rocketroll-split/1:"


class ChecksumError(RocketrollError, ValueError):
    """A trace's samples do not match its checksum."""


def checksum(samples: ArrayLike) -> str:
    """SHA-256 (hex) of the stored bytes of a trace: little-endian float64."""
    return hashlib.sha256(np.ascontiguousarray(samples, dtype="<f8").tobytes()).hexdigest()


def content_hash(columns: Mapping[str, ArrayLike]) -> str:
    """SHA-256 (hex) of a recording's samples: column names and float64 values.

    Name, source and metadata are not part of it: the same samples are the
    same recording.
    """
    h = hashlib.sha256(b"rocketroll-recording-samples/1\n")
    for name in sorted(columns):
        h.update(name.encode() + b"\n")
        h.update(np.ascontiguousarray(columns[name], dtype="<f8").tobytes())
    return h.hexdigest()


def split_of(recording_hash: str, test_fraction: float = TEST_FRACTION) -> str:
    """``train`` or ``test`` for a recording, from its content hash alone."""
    digest = hashlib.sha256(_SPLIT_SALT + recording_hash.encode()).digest()
    u = int.from_bytes(digest[:8], "big") / 2.0**64
    return "test" if u < test_fraction else "train"


def json_safe(value: Any) -> Any:
    """``value`` with NaN and infinities as ``None`` and tuples as lists (strict JSON)."""
    if isinstance(value, float | np.floating):
        f = float(value)
        return f if math.isfinite(f) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, Mapping):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [json_safe(v) for v in value]
    return value


def _frozen(mapping: Mapping[str, Any]) -> Mapping[str, Any]:
    return MappingProxyType(dict(mapping))


class _Row:
    """Rows compare by value (sample arrays element by element) and pickle (a bank goes
    to subprocess vector envs) with their read-only mappings."""

    __hash__ = None  # type: ignore[assignment]

    def __getstate__(self) -> dict[str, Any]:
        return {k: dict(v) if isinstance(v, MappingProxyType) else v for k, v in vars(self).items()}

    def __setstate__(self, state: dict[str, Any]) -> None:
        for k, v in state.items():
            object.__setattr__(self, k, MappingProxyType(v) if isinstance(v, dict) else v)

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        for f in fields(self):  # type: ignore[arg-type]
            a, b = getattr(self, f.name), getattr(other, f.name)
            if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
                if a is None or b is None or not np.array_equal(a, b):
                    return False
            elif a != b:
                return False
        return True


@dataclass(frozen=True, eq=False)
class RecordingRow(_Row):
    """A recording as stored: its samples, exactly, with name, source and metadata.

    Attributes
    ----------
    content_hash : str
        :func:`content_hash` of ``samples`` (checked on construction).
    name, source : str
        As in the recording file.
    metadata : mapping of str to str
        The recording's other ``# key: value`` lines.
    columns : tuple of str
        Column names, ``time_s`` first.
    samples : ndarray, shape (n, len(columns)), or None
        The values, float64; None in a listing.
    added_at : str
        When it entered the database (UTC, ISO 8601).
    n_samples, dt_s, duration_s : int, float, float
        Length, median sampling interval (s) and span (s); computed from the
        samples when they are given.
    split : str
        ``train`` or ``test``: the recording's ``split`` metadata if it has
        one, else :func:`split_of` its content hash (computed when not given).
    id : int or None
        Row id in the database it was read from.
    """

    content_hash: str
    name: str
    source: str
    metadata: Mapping[str, str]
    columns: tuple[str, ...]
    samples: FloatArray | None
    added_at: str
    n_samples: int = 0
    dt_s: float = 0.0
    duration_s: float = 0.0
    split: str = ""
    id: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "metadata", _frozen(self.metadata))
        object.__setattr__(self, "columns", tuple(self.columns))
        if self.source not in SOURCES:
            raise ValueError(
                f"recording {self.name!r}: source must be one of {', '.join(SOURCES)}, "
                f"not {self.source!r}"
            )
        if self.samples is not None:
            object.__setattr__(self, "samples", readonly_array(self.samples))
            if self.samples.ndim != 2 or self.samples.shape[1] != len(self.columns):
                raise ValueError(
                    f"recording {self.name!r}: samples of shape {self.samples.shape} do not "
                    f"match {len(self.columns)} columns"
                )
            actual = content_hash(self.column_dict())
            if actual != self.content_hash:
                raise ValueError(
                    f"recording {self.name!r}: content hash {self.content_hash[:12]}… does not "
                    f"match its samples ({actual[:12]}…)"
                )
            time = self.samples[:, 0]
            object.__setattr__(self, "n_samples", int(self.samples.shape[0]))
            object.__setattr__(self, "dt_s", float(np.median(np.diff(time))))
            object.__setattr__(self, "duration_s", float(time[-1] - time[0]))
        declared = self.metadata.get("split")
        rule = declared if declared in SPLITS else split_of(self.content_hash)
        if not self.split:
            object.__setattr__(self, "split", rule)
        elif self.split != rule:
            raise ValueError(
                f"recording {self.name!r}: split {self.split!r} differs from its rule ({rule!r})"
            )

    @classmethod
    def of(cls, recording: Recording, added_at: str) -> RecordingRow:
        """The row for a :class:`~identification.recordings.recording.Recording`."""
        columns = recording.columns()
        return cls(
            content_hash=content_hash(columns),
            name=recording.name,
            source=recording.source,
            metadata=dict(recording.metadata),
            columns=tuple(columns),
            samples=np.column_stack(list(columns.values())),
            added_at=added_at,
        )

    def column_dict(self) -> dict[str, FloatArray]:
        """``{column: values}`` (the samples must have been read)."""
        samples = self.sample_array()
        return {name: samples[:, i] for i, name in enumerate(self.columns)}

    def recording(self) -> Recording:
        """The :class:`~identification.recordings.recording.Recording` (validated again)."""
        return Recording(
            name=self.name, source=self.source, metadata=self.metadata, **self.column_dict()
        )

    def sample_array(self) -> FloatArray:
        """``samples``, which must have been read (:meth:`DisturbanceDB.recording_row`)."""
        if self.samples is None:
            raise ValueError(f"recording {self.name!r}: its samples were not read")
        return self.samples


@dataclass(frozen=True, eq=False)
class IdentificationRow(_Row):
    """One identified model of one recording.

    Attributes
    ----------
    recording_hash : str
        The recording it was identified from.
    method : str
        The identification method (:data:`identification.methods.METHODS`).
    model : str
        ``constant`` or ``theta`` (:data:`identification.model.MODELS`).
    params : RollParams
        α, θ̄, β̄ (or the constant ``a``) and ᾱ.
    metrics : mapping
        Fit metrics (JSON-safe): R², re-simulation errors, the noise study, ...
    options : mapping
        The :class:`~identification.methods.pipeline.IdentifyOptions` used (JSON-safe).
    package_version : str
        The rocketroll version that identified it.
    created_at : str
        UTC, ISO 8601.
    recording : str
        The recording's name (read from a database).
    id : int or None
        Row id in the database it was read from.
    """

    recording_hash: str
    method: str
    model: str
    params: RollParams
    metrics: Mapping[str, Any]
    options: Mapping[str, Any]
    package_version: str
    created_at: str
    recording: str = ""
    id: int | None = None

    def __post_init__(self) -> None:
        if not self.method:
            raise ValueError("an identification needs a method name")
        check_model(self.model)
        object.__setattr__(self, "metrics", _frozen(json_safe(self.metrics)))
        object.__setattr__(self, "options", _frozen(json_safe(self.options)))
        if self.verdict not in (None, *VERDICTS):
            raise ValueError(f"adequacy verdict {self.verdict!r}: must be one of {VERDICTS}")

    @property
    def verdict(self) -> str | None:
        """The fit's adequacy verdict (good, weak, unreliable:
        :mod:`identification.methods.adequacy`) from its metrics; ``None`` where it was not
        assessed (a flight fit, an old row)."""
        figures = self.metrics.get("adequacy")
        return None if not isinstance(figures, Mapping) else figures.get("verdict")

    @property
    def accepted_unreliable(self) -> bool:
        """Whether it was stored although every fit of its recording was judged unreliable,
        because the user said so (``rocketroll db add --accept-unreliable``: the metric
        :data:`ACCEPTED_UNRELIABLE`)."""
        return self.metrics.get(ACCEPTED_UNRELIABLE) is True

    @property
    def flight_reference(self) -> FlightReference | None:
        """Where a flight fit's parameters hold and how they scale (from its metrics);
        None for a tunnel fit."""
        return FlightReference.from_metrics(self.metrics)

    @property
    def key(self) -> tuple[str, str, str]:
        """``(recording_hash, method, model)``: unique in a database."""
        return (self.recording_hash, self.method, self.model)


def identified_uid(recording_hash: str, method: str, model: str) -> str:
    """The uid of the trace identified by ``method``/``model`` from a recording."""
    return f"{recording_hash[:12]}-{method}-{model}"


def surrogate_uid(source_uid: str, kind: str, seed: int) -> str:
    """The uid of surrogate number ``seed`` of kind ``kind`` made from ``source_uid``."""
    return f"{source_uid}-{kind}-{seed}"


def posterior_uid(source_uid: str, seed: int) -> str:
    """The uid of the posterior draw of seed ``seed`` that goes with trace ``source_uid``."""
    return surrogate_uid(source_uid, POSTERIOR_KIND, seed)


#: Keys of a trace's ``statistics``.
STATISTICS = ("mean_deg", "sd_deg", "q05_deg", "q95_deg", "normality_p")


def plain_statistics(u_d_deg: FloatArray) -> dict[str, float | None]:
    """A trace's ``statistics`` without the normality test (``normality_p`` None): for
    traces made in memory (bare arrays, flown traces), not stored."""
    u = np.asarray(u_d_deg, dtype=float)
    return {
        "mean_deg": float(u.mean()),
        "sd_deg": float(u.std()),
        "q05_deg": float(np.percentile(u, 5)),
        "q95_deg": float(np.percentile(u, 95)),
        "normality_p": None,
    }


@dataclass(frozen=True, eq=False)
class TraceRow(_Row):
    """One ``u_d`` trace: identified from a recording, or a surrogate of another trace.

    Attributes
    ----------
    uid : str
        Stable identity, the same in every database and export (see the
        module docstring).
    recording_hash, method, model : str
        The identification whose parameters go with it (for a surrogate:
        its source's).
    kind : str
        ``identified``, ``iaaft``, ``ar`` or ``posterior``.
    source_uid : str or None
        The trace a surrogate was made from, or the identified (posterior-mean)
        trace a posterior draw goes with; ``None`` for an identified one.
    seed : int or None
        The surrogate's or posterior draw's seed.
    settings : mapping
        How it was made (JSON-safe).
    dt_s : float
        Δt over which each sample of ``u_d`` is held, s (eq. 44: 0.1).
    t0_s : float
        Start of the first interval, s (recording time).
    checksum : str
        :func:`checksum` of the samples (checked whenever they are present).
    statistics : mapping
        ``mean_deg``, ``sd_deg``, ``q05_deg``, ``q95_deg``, ``normality_p``
        (Lilliefors on the thinned trace; ``None`` if it could not be computed).
    validation : mapping or None
        A surrogate's check against its source (KS p-value, PSD
        log-distance, ``passed``); ``None`` for an identified trace.
    created_at : str
        UTC, ISO 8601.
    u_d_deg : ndarray, shape (n,), or None
        The trace, ° of equivalent fin angle, each sample held for ``dt_s``
        (read-only); None in a listing.
    n_samples : int
        Length (from ``u_d_deg`` when given).
    params : RollParams or None
        The parameters identified together with it (its identification's).
    recording, source, split : str
        Its recording's name, source and split (for a surrogate: its
        source's).
    package_version : str
        The rocketroll version that identified it.
    verdict : str or None
        Its identification's adequacy verdict (``None``: not assessed).
    id : int or None
        Row id in the database it was read from (use ``uid`` across databases).
    recording_id : int or None
        Its recording's row id there (use ``recording_hash`` across databases).
    flight_reference : FlightReference or None
        A flight fit's reference airspeed, density and scaling, where its ``params``
        hold (None: a tunnel fit, at the tunnel's airspeed).
    rig : Rig
        The rig its identification assumed: the fin's linkage and the sensors' latency
        (stated by the recording or the identification's settings; all 0 by default),
        which a replay flies.
    """

    uid: str
    recording_hash: str
    method: str
    model: str
    kind: str
    source_uid: str | None
    seed: int | None
    settings: Mapping[str, Any]
    dt_s: float
    t0_s: float
    checksum: str
    statistics: Mapping[str, Any]
    validation: Mapping[str, Any] | None
    created_at: str = ""
    u_d_deg: FloatArray | None = None
    n_samples: int = 0
    params: RollParams | None = None
    recording: str = ""
    source: str = ""
    split: str = ""
    package_version: str = ""
    verdict: str | None = None
    id: int | None = None
    recording_id: int | None = None
    flight_reference: FlightReference | None = None
    rig: Rig = field(default_factory=Rig)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"trace {self.uid}: kind must be one of {', '.join(KINDS)}")
        if (self.kind == "identified") != (self.source_uid is None):
            raise ValueError(
                f"trace {self.uid}: only a surrogate or a posterior draw has a source trace"
            )
        check_model(self.model)
        if not (math.isfinite(self.dt_s) and self.dt_s > 0):
            raise ValueError(f"trace {self.uid}: dt_s must be positive, got {self.dt_s!r}")
        if self.u_d_deg is not None:
            object.__setattr__(self, "u_d_deg", readonly_array(self.u_d_deg))
            u = self.u_d_deg
            if u.ndim != 1 or u.size < 2:
                raise ValueError(f"trace {self.uid}: needs a 1-D trace of at least 2 samples")
            if not np.all(np.isfinite(u)):
                raise ValueError(f"trace {self.uid}: has NaN or infinite samples")
            actual = checksum(u)
            if actual != self.checksum:
                raise ChecksumError(
                    f"trace {self.uid}: checksum {self.checksum[:12]}… does not match its "
                    f"samples ({actual[:12]}…)"
                )
            object.__setattr__(self, "n_samples", int(u.size))
        missing = [k for k in STATISTICS if k not in self.statistics]
        if missing:
            raise ValueError(f"trace {self.uid}: statistics lack {', '.join(missing)}")
        object.__setattr__(self, "settings", _frozen(json_safe(self.settings)))
        object.__setattr__(self, "statistics", _frozen(json_safe(self.statistics)))
        if self.validation is not None:
            object.__setattr__(self, "validation", _frozen(json_safe(self.validation)))

    @property
    def identification_key(self) -> tuple[str, str, str]:
        """``(recording_hash, method, model)`` of its parameters."""
        return (self.recording_hash, self.method, self.model)

    @property
    def duration_s(self) -> float:
        """Length of the trace, s."""
        return self.n_samples * self.dt_s

    @property
    def mean_deg(self) -> float:
        """Mean of ``u_d``, °."""
        return float(self.statistics["mean_deg"])

    @property
    def sd_deg(self) -> float:
        """Standard deviation of ``u_d``, °."""
        return float(self.statistics["sd_deg"])

    @property
    def q05_deg(self) -> float:
        """5 % quantile of ``u_d``, °."""
        return float(self.statistics["q05_deg"])

    @property
    def q95_deg(self) -> float:
        """95 % quantile of ``u_d``, °."""
        return float(self.statistics["q95_deg"])

    @property
    def normality_p(self) -> float | None:
        """Lilliefors p-value on the thinned trace (None if it could not be computed)."""
        p = self.statistics.get("normality_p")
        return None if p is None else float(p)

    def samples(self) -> FloatArray:
        """``u_d_deg``, which must have been read (:meth:`DisturbanceDB.trace`)."""
        if self.u_d_deg is None:
            raise ValueError(f"trace {self.uid}: its samples were not read")
        return self.u_d_deg

    def rocket(self) -> RollParams:
        """``params``, which a row read from a database always has."""
        if self.params is None:
            raise ValueError(f"trace {self.uid}: its parameters are not known")
        return self.params

    def __repr__(self) -> str:
        return (
            f"TraceRow(uid={self.uid!r}, kind={self.kind}, {self.method}/{self.model}, "
            f"split={self.split or '?'}, n={self.n_samples}, dt={self.dt_s:g} s)"
        )


def derived_row(
    source: TraceRow,
    u: FloatArray,
    dt_s: float,
    suffix: str | None,
    settings: Mapping[str, Any],
) -> TraceRow:
    """A trace made from ``source`` (flown in a flight, averaged onto another grid): its
    rocket and provenance, the samples ``u`` held ``dt_s`` each, uid ``<source
    uid>@<suffix>`` (the source's own without one: the same turbulence on another grid),
    ``settings`` added to the source's (in memory only: such traces are made per
    configuration, not stored)."""
    return dataclasses.replace(
        source,
        uid=source.uid if suffix is None else f"{source.uid}@{suffix}",
        dt_s=float(dt_s),
        t0_s=0.0,
        u_d_deg=u,
        checksum=checksum(u),
        settings={**dict(source.settings), **settings},
        statistics=plain_statistics(u),
        id=None,
    )


def params_from_columns(columns: Any) -> RollParams:
    """The roll parameters an identification's stored columns hold (``columns[name]``)."""
    return RollParams(
        columns["alpha"],
        columns["theta_bar_deg"],
        columns["beta_bar_per_s"],
        columns["alpha_bar_per_deg_s"],
        columns["quadratic_damping"],
    )


def rig_from_json(options: str, recording_metadata: str, metrics: str = "{}") -> Rig:
    """The rig of an identification's stored options, its recording's metadata and the
    fit's metrics (JSON): what was stated, with what the fit's method found
    (:func:`~identification.methods.pipeline.fitted_rig`)."""
    from identification.methods.pipeline import fitted_rig

    rig = Rig.resolved(json.loads(options).get("rig") or {}, json.loads(recording_metadata))
    return fitted_rig(rig, json.loads(metrics))
