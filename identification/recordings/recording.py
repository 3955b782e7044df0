"""Roll recording format v1 (and its minor version 1.1, for flights): load, validate, save.

A recording is a UTF-8 CSV file::

    # format: rocketroll-recording/1
    # name: tunnel-paper-seed0
    # source: synthetic
    # notes: anything
    # truth.alpha: 0.659
    time_s,fin_cmd_deg,roll_deg
    0,0,0
    0.1,0,0
    ...

* Leading ``# key: value`` lines carry metadata.  ``source`` is required and is
  one of ``synthetic``, ``wind-tunnel``, ``flight``; ``name`` defaults to the
  file's stem; any other key (``notes``, ``seed``, ``truth.*``, ...) is kept
  verbatim.  Keys use letters, digits and ``_ . -``.
* One header row, then one row per sample, comma separated, every cell a
  finite number.
* Columns (see :data:`COLUMNS`): ``time_s`` and at least one fin column and
  one roll column.  ``ud_true_deg`` (the tunnel's ground-truth disturbance)
  is only allowed in synthetic recordings.
* Format 1.1 adds a flight's ``airspeed_mps`` (required for a flight
  identification: the roll model's gain and damping scale with it, eq. 4-8)
  and ``altitude_m`` (optional, for the density; needs ``airspeed_mps``).
  A file with either says ``# format: rocketroll-recording/1.1``; a file
  without them is written as ``rocketroll-recording/1``, byte for byte as
  before, and both are read.
* Format 1.2 adds the rig's description: ``rig.servo_lag_s``,
  ``rig.backlash_deg`` and ``rig.sensor_latency_s`` (what the user states of
  the fin's linkage and the roll sensors' latency, from bench tests or data
  sheets: :class:`identification.model.Rig`), used by identification and
  replay, and ``rig.fin_range_deg`` (the fins' range, ± this: what the
  identification's adequacy measures ``u_d`` against, :meth:`Recording.fin_range`).
  A file with any of them says ``# format: rocketroll-recording/1.2``.
* Time strictly increasing and uniformly sampled within
  :data:`SAMPLING_RTOL` of the median interval; at least :data:`MIN_SAMPLES`
  samples; a fin angle that changes by at least :data:`MIN_FIN_CHANGE_DEG`.

Every problem raises :class:`RecordingError`, whose message names the file,
the line and the problem.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from types import MappingProxyType

import numpy as np
from numpy.typing import ArrayLike, NDArray

from identification.model import RIG_KEYS, RIG_LIMITS, Rig, RollParams, Servo
from rocketroll_common.arrays import FloatArray, readonly_array
from rocketroll_common.errors import RocketrollError, SettingError, UsageError
from rocketroll_common.files import write_atomic
from rocketroll_common.settings import check, setting
from rocketroll_common.text import parse_number

__all__ = [
    "COLUMNS",
    "FIN_RANGE_KEY",
    "FLIGHT_COLUMNS",
    "FORMAT",
    "FORMATS",
    "FORMAT_V1",
    "FORMAT_V1_2",
    "MAX_ABS",
    "MAX_FIN_RANGE_DEG",
    "MAX_RATE_DPS",
    "MIN_FIN_CHANGE_DEG",
    "MIN_SAMPLES",
    "PLAUSIBLE_FIN_DEG",
    "RIG_METADATA",
    "SAMPLING_RTOL",
    "SOURCES",
    "STEADY_AIRSPEED_RTOL",
    "FinRange",
    "LoopFlags",
    "Recording",
    "RecordingError",
    "StatedLoop",
    "StatedRig",
    "fin_range_setting",
    "load_recording",
    "quantum_of",
    "read_text",
    "save_recording",
    "small_fins",
    "validate_samples",
]

#: Format 1: the tunnel's recordings (written for every recording without flight columns).
FORMAT_V1 = "rocketroll-recording/1"
#: Format 1.1: format 1 plus the flight columns :data:`FLIGHT_COLUMNS`.
FORMAT = "rocketroll-recording/1.1"
#: Format 1.2: format 1.1 plus the rig's description, the ``rig.*`` metadata lines
#: (:data:`identification.model.RIG_KEYS`): what the user states of the fin's linkage and the
#: sensors' latency.
FORMAT_V1_2 = "rocketroll-recording/1.2"
#: Every format this package reads.
FORMATS = (FORMAT_V1, FORMAT, FORMAT_V1_2)
#: The ``rig.*`` line of the fins' range, ° (± this): what the user states of the rig
#: (``import-csv``/``identify --fin-range``).  No :class:`identification.model.Rig` field:
#: the identification's adequacy reads it (:meth:`Recording.fin_range`), the environments
#: keep their own fin range.
FIN_RANGE_KEY = "rig.fin_range_deg"
#: The widest fins' range a recording states, °: its fin columns stay within ±90°.
MAX_FIN_RANGE_DEG = 90.0
#: The ``rig.*`` metadata keys format 1.2 adds, with their upper bounds.
RIG_METADATA: Mapping[str, float] = MappingProxyType(
    {key: RIG_LIMITS[f] for f, (_, key) in RIG_KEYS.items()} | {FIN_RANGE_KEY: MAX_FIN_RANGE_DEG}
)


def fin_range_setting(help: str) -> float | None:
    """The ``--fin-range DEG`` setting (``import-csv``, ``identify``) with ``help``: in
    (0, :data:`MAX_FIN_RANGE_DEG`] °, None where not stated."""
    result: float | None = setting(
        None, help, flag="--fin-range", gt=0.0, le=MAX_FIN_RANGE_DEG, unit="°", metavar="DEG"
    )
    return result


@dataclass(frozen=True)
class FinRange:
    """The fins' range, ±``deg`` °, and where it comes from (``source``: :attr:`STATED`,
    :attr:`TRUTH` or :attr:`LARGEST`); ``str()`` gives both, e.g. ``±15° (stated)``."""

    deg: float
    source: str

    #: Stated by the user: ``--fin-range``, or the recording's ``rig.fin_range_deg`` line.
    STATED = "stated"
    #: A virtual instrument's own servo (a synthetic recording's truth).
    TRUTH = "the virtual instrument's truth"
    #: Nothing states it: the largest ``|fin|`` the log holds (a lower bound of the range).
    LARGEST = "the log's largest |fin|"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.deg) and self.deg > 0.0):
            raise ValueError(f"FinRange.deg must be > 0, got {self.deg!r}")
        if self.source not in (self.STATED, self.TRUTH, self.LARGEST):
            raise ValueError(f"FinRange.source must be one of the known, got {self.source!r}")

    def __str__(self) -> str:
        return f"±{self.deg:g}° ({self.source})"

    @property
    def hint(self) -> str:
        """How to state it, where nothing does (else empty)."""
        if self.source != self.LARGEST:
            return ""
        return "; state your fins' range with import-csv or identify --fin-range DEG"

    def as_dict(self) -> dict[str, float | str]:
        """``fin_range_deg`` and ``fin_range_source`` (JSON)."""
        return {"fin_range_deg": self.deg, "fin_range_source": self.source}


#: How close to a stop (°) a logged command counts as saturated (:meth:`StatedLoop.excitation`).
AT_STOP_DEG = 0.01
#: The ``loop.*`` metadata lines that state a flight computer's proportional roll-rate loop on
#: the fins (:class:`StatedLoop`), numbers with their bounds (``None``: any finite number);
#: other ``loop.*`` lines (its law, the sensor it reads) are free text.
LOOP_METADATA: Mapping[str, tuple[float, float] | None] = MappingProxyType(
    {
        "loop.gain": None,
        "loop.delay_s": (0.0, RIG_METADATA["rig.sensor_latency_s"]),
        "loop.stops_deg": (0.0, MAX_FIN_RANGE_DEG),
    }
)


@dataclass(frozen=True)
class StatedLoop:
    """A flight computer's proportional roll-rate loop on the fins, as the user states it
    (``identify --loop-gain/--loop-delay``) or the recording's ``loop.*`` lines do: the fin
    command ``clip(e(t) + gain·(0 − rate read delay_s before), ±stops)``, ``e`` the
    excitation on top of the loop (a dither, a schedule; 0 where there is none).

    ``gain`` in ° of fin per °/s, ``delay_s`` from the gyro's reading to the command,
    ``stops_deg`` where the command saturates (None: not stated; the fins' range is used)."""

    gain: float
    delay_s: float = 0.0
    stops_deg: float | None = None

    @classmethod
    def of(cls, metadata: Mapping[str, str]) -> StatedLoop | None:
        """The loop the ``loop.*`` lines of ``metadata`` state (None without ``loop.gain``)."""
        if "loop.gain" not in metadata:
            return None
        stops = metadata.get("loop.stops_deg")
        return cls(
            parse_number(metadata["loop.gain"]),
            parse_number(metadata.get("loop.delay_s", "0")),
            None if stops is None else parse_number(stops),
        )

    def excitation(
        self, time_s: ArrayLike, command_deg: ArrayLike, rate_dps: ArrayLike, stops_deg: float
    ) -> tuple[FloatArray, FloatArray]:
        """The excitation ``e`` on top of the loop at each sample, given back from the logged
        command and the logged rate read ``delay_s`` before (linearly between samples, the
        first one before the log): ``e = command + gain·rate(t − delay)``; and where the
        command sat at ``stops_deg`` (there ``e`` is not known, only that the loop asked for
        more than the stops: flagged True)."""
        time = np.asarray(time_s, dtype=float)
        command = np.asarray(command_deg, dtype=float)
        reading = np.interp(time - self.delay_s, time, np.asarray(rate_dps, dtype=float))
        saturated = np.abs(command) >= stops_deg - AT_STOP_DEG
        return command + self.gain * reading, saturated  # the inverse of :meth:`command`

    def stops_within(self, fins: FinRange) -> float:
        """Where the command saturates: the loop's stated stops, else the fins' range."""
        return self.stops_deg or fins.deg

    def command(self, excitation_deg: float, reading_dps: float, stops_deg: float) -> float:
        """The loop's law: the command for the excitation and the rate it read."""
        return min(max(excitation_deg - self.gain * reading_dps, -stops_deg), stops_deg)

    def metadata(self) -> dict[str, str]:
        """The ``loop.*`` lines that state it."""
        lines = {"loop.gain": repr(float(self.gain)), "loop.delay_s": repr(float(self.delay_s))}
        if self.stops_deg is not None:
            lines["loop.stops_deg"] = repr(float(self.stops_deg))
        return lines


@dataclass(frozen=True)
class LoopFlags:
    """The flags that state a flight computer's rate loop (``import-csv`` stores them in the
    recording's ``loop.*`` lines, ``identify`` states them over the recording's own)."""

    loop_gain: float | None = setting(
        None,
        "your flight computer's proportional roll-rate loop on the fins: fin command = "
        "excitation + this × (0 - rate read --loop-delay earlier), saturated at the fins' "
        "range; the instrumental method then takes the excitation as its instrument",
        flag="--loop-gain", ge=-100.0, le=100.0, unit="°/(°/s)", metavar="K",
    )  # fmt: skip
    loop_delay_s: float | None = setting(
        None,
        "that loop's delay from the gyro's reading to the command (default with --loop-gain: 0)",
        flag="--loop-delay", ge=0.0, le=RIG_METADATA["rig.sensor_latency_s"], unit="s",
        metavar="S",
    )  # fmt: skip

    def __post_init__(self) -> None:
        check(self)
        if self.loop_gain == 0.0:
            raise SettingError("loop_gain", "0 is no loop; leave it out for an open-loop test")

    def stated(self, own: StatedLoop | None, where: str) -> StatedLoop | None:
        """The loop the flags state over ``own`` (a recording's, at ``where``): None where
        neither flag is given; ``--loop-delay`` alone needs a loop to delay."""
        if self.loop_gain is None and self.loop_delay_s is None:
            return None
        gain = self.loop_gain if self.loop_gain is not None else own.gain if own else None
        if gain is None:
            raise UsageError(
                f"--loop-delay: {where} states no loop (no loop.gain line); give --loop-gain too"
            )
        delay = self.loop_delay_s if self.loop_delay_s is not None else own.delay_s if own else 0.0
        return StatedLoop(gain, delay, own.stops_deg if own else None)


@dataclass(frozen=True)
class StatedRig:
    """What a user states of the rig (a bench test's or data sheet's), each None where not
    stated: the flags of ``rocketroll import-csv`` (stored in the recording's ``rig.*``
    lines) and ``rocketroll identify`` (over the recording's own)."""

    servo_lag_s: float | None = setting(
        None, "your rig's fin lag behind the servo (a bench test's time constant)",
        flag="--servo-lag", ge=0.0, le=RIG_METADATA["rig.servo_lag_s"], unit="s", metavar="S",
    )  # fmt: skip
    backlash_deg: float | None = setting(
        None, "your rig's play between servo and fin",
        flag="--backlash", ge=0.0, le=RIG_METADATA["rig.backlash_deg"], unit="°", metavar="DEG",
    )  # fmt: skip
    sensor_latency_s: float | None = setting(
        None, "your roll sensors' delay (the rocket they read is the one of this long ago)",
        flag="--sensor-latency", ge=0.0, le=RIG_METADATA["rig.sensor_latency_s"], unit="s",
        metavar="S",
    )  # fmt: skip

    def __post_init__(self) -> None:
        check(self)

    @classmethod
    def of(cls, rig: Rig) -> StatedRig:
        """All of ``rig`` stated."""
        return cls(**{setting: getattr(rig, f) for f, (setting, _) in RIG_KEYS.items()})

    def metadata(self) -> dict[str, str]:
        """The ``rig.*`` lines of what is stated."""
        return {
            key: repr(float(getattr(self, setting)))
            for setting, key in RIG_KEYS.values()
            if getattr(self, setting) is not None
        }


SOURCES = ("synthetic", "wind-tunnel", "flight")

#: Column name -> meaning.  Order here is the order in which files are written.
COLUMNS: Mapping[str, str] = MappingProxyType(
    {
        "time_s": "sample time, s",
        "fin_cmd_deg": "commanded fin angle, ° (the servo lag of eq. 23 applies)",
        "fin_deg": "measured actual fin angle, °",
        "roll_deg": "roll angle from the encoder, °",
        "roll_rate_dps": "roll rate from a rate gyro, °/s",
        "airspeed_mps": "airspeed of a flight, m/s (format 1.1)",
        "altitude_m": "altitude above sea level of a flight, m, for the ISA density "
        "(format 1.1; needs airspeed_mps)",
        "ud_true_deg": "ground-truth disturbance u_d, ° (synthetic recordings only)",
    }
)
FIN_COLUMNS = ("fin_cmd_deg", "fin_deg")
ROLL_COLUMNS = ("roll_deg", "roll_rate_dps")
#: The columns format 1.1 adds.
FLIGHT_COLUMNS = ("airspeed_mps", "altitude_m")
#: Allowed range of each flight column (the altitudes the ISA of
#: :mod:`rocketroll_physics.atmosphere` covers).
FLIGHT_RANGES: Mapping[str, tuple[float, float]] = MappingProxyType(
    {"airspeed_mps": (0.0, 2_000.0), "altitude_m": (-500.0, 20_000.0)}
)

#: Largest allowed relative deviation of a sampling interval from the median.
SAMPLING_RTOL = 0.01
#: An airspeed whose 1st-99th percentile spread stays within this fraction of its median
#: is a tunnel's steady one (a fan's wobble and a sensor's noise), not a flight.
STEADY_AIRSPEED_RTOL = 0.1
#: Fewest samples a recording may have.
MIN_SAMPLES = 50
#: Median sampling interval a recording may have, s: a roll log is sampled at 1 kHz to 1 Hz.
#: Outside, the time column is most likely in another unit (ms read as s: 100 s a step), and
#: the work would run away (a fine grid of 10 ms steps over 573 000 s).
INTERVAL_RANGE_S = (1e-3, 1.0)
#: Duration a recording may have, s: 4.9 s (50 samples at 10 Hz) to a day.
DURATION_RANGE_S = (4.9, 86_400.0)
#: Smallest fin-angle range (max - min) that gives something to identify, °.
MIN_FIN_CHANGE_DEG = 0.1
#: A fin column whose 99th percentile of ``|value|`` stays under this, °, is implausible for
#: a roll experiment: a fin in radians read as degrees (±10° reads ±0.17) looks like this.
PLAUSIBLE_FIN_DEG = 1.0

#: Largest plausible roll rate, °/s: beyond what the paper's encoder is rated for
#: (12 000 °/s, §2.1) and any sounding rocket's roll.  Faster rates -- read by a gyro
#: or implied by the encoder angle between two samples -- are refused, not fitted.
MAX_RATE_DPS = 20_000.0
#: Largest plausible value of each column (absolute), in its unit.
MAX_ABS: Mapping[str, float] = MappingProxyType(
    {
        "time_s": 1e12,
        "fin_cmd_deg": 90.0,
        "fin_deg": 90.0,
        "roll_deg": 1e9,
        "roll_rate_dps": MAX_RATE_DPS,
        "airspeed_mps": FLIGHT_RANGES["airspeed_mps"][1],
        "altitude_m": FLIGHT_RANGES["altitude_m"][1],
        "ud_true_deg": 1e5,
    }
)

#: Decimals written for time_s (values: 6).
TIME_DECIMALS = 9

_KEY = re.compile(r"^[A-Za-z0-9_.\-]+$")
_RESERVED = ("format", "name", "source")


class RecordingError(RocketrollError, ValueError):
    """A recording (or the data for one) is invalid.

    Attributes
    ----------
    path : str
        The file, or a description such as ``"<recording>"``.
    line : int or None
        1-based line number in ``path`` where the problem is, if it has one.
    problem : str
        What is wrong.
    """

    def __init__(self, path: str | os.PathLike[str], line: int | None, problem: str) -> None:
        self.path = os.fspath(path)
        self.line = line
        self.problem = problem
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {problem}")

    def __reduce__(
        self,
    ) -> tuple[type[RecordingError], tuple[str, int | None, str], dict[str, object]]:
        """Pickled with its own arguments and its state, notes included (an error raised in a
        worker process crosses back whole)."""
        return type(self), (self.path, self.line, self.problem), dict(vars(self))


def _where(lines: NDArray[np.int64] | None, index: int) -> int | None:
    return None if lines is None else int(lines[index])


def _descent_hint(name: str, values: NDArray[np.float64], time: NDArray[np.float64], i: int) -> str:
    """What a negative airspeed after the flight's fastest means (an airspeed integrated
    from the accelerometer: the vertical speed, negative on the way down), and the cut that
    keeps the ascent; empty for anything else."""
    fastest = int(np.argmax(values))
    if name != "airspeed_mps" or values[i] >= 0 or i <= fastest or values[fastest] < 10.0:
        return ""
    return (
        f": the descent after apogee (the fastest, {values[fastest]:.1f} m/s, at "
        f"{time[fastest]:g} s), where an airspeed integrated from the accelerometer goes "
        f"negative; keep the ascent with import-csv --to "
        f"{np.format_float_positional(time[i - 1], trim='-')}"
    )


def _sample(lines: NDArray[np.int64] | None, index: int) -> str:
    return "" if lines is not None else f"sample {index}: "


def quantum_of(values: FloatArray) -> float:
    """The encoder's resolution: the step of the grid the angle values lie on (0 if none)."""
    levels = np.unique(values)
    if levels.size < 3:
        return 0.0
    steps = np.diff(levels)
    q = float(np.min(steps))
    if q <= 0.0:
        return 0.0
    ratio = steps / q
    if float(np.max(np.abs(ratio - np.round(ratio)))) > 1e-3:
        return 0.0  # not on a grid: an unquantised (or already processed) angle
    return q


def small_fins(columns: Mapping[str, FloatArray | None]) -> dict[str, float]:
    """The fin columns (of :data:`FIN_COLUMNS` present in ``columns``) whose 99th percentile
    of ``|value|`` stays under :data:`PLAUSIBLE_FIN_DEG`, with that percentile, °: an
    implausible fin range, most likely radians read as degrees."""
    found = {}
    for name in FIN_COLUMNS:
        values = columns.get(name)
        if values is not None and np.size(values):
            p99 = float(np.percentile(np.abs(values), 99.0))
            if p99 < PLAUSIBLE_FIN_DEG:
                found[name] = p99
    return found


def _check_column_set(
    columns: Mapping[str, FloatArray],
    path: str,
    header_line: int | None,
    source: str | None,
    version: str | None,
) -> None:
    """The columns a recording has: known ones, the required ones, the flight's with its
    format, the altitude with the airspeed, the truth only in synthetic data."""
    unknown = [c for c in columns if c not in COLUMNS]
    if unknown:
        raise RecordingError(
            path,
            header_line,
            f"unknown column {unknown[0]!r}; allowed columns: {', '.join(COLUMNS)}",
        )
    missing = []
    if "time_s" not in columns:
        missing.append("time_s")
    if not any(c in columns for c in FIN_COLUMNS):
        missing.append(" or ".join(FIN_COLUMNS))
    if not any(c in columns for c in ROLL_COLUMNS):
        missing.append(" or ".join(ROLL_COLUMNS))
    if missing:
        raise RecordingError(
            path, header_line, f"missing column {'; missing column '.join(missing)}"
        )
    flight = [c for c in FLIGHT_COLUMNS if c in columns]
    if flight and version is not None and version not in (FORMAT, FORMAT_V1_2):
        raise RecordingError(
            path,
            header_line,
            f"column {flight[0]!r} is format 1.1: the file must say '# format: {FORMAT}', "
            f"not {version!r}",
        )
    if "altitude_m" in columns and "airspeed_mps" not in columns:
        raise RecordingError(
            path,
            header_line,
            "column 'altitude_m' needs the column 'airspeed_mps' (a flight's altitude "
            "gives the density; without the airspeed there is nothing to scale)",
        )
    if "ud_true_deg" in columns and source is not None and source != "synthetic":
        raise RecordingError(
            path,
            header_line,
            f"column 'ud_true_deg' is only allowed when source is synthetic, not {source!r}",
        )


def _check_values(
    columns: Mapping[str, FloatArray],
    path: str,
    lines: NDArray[np.int64] | None,
    header_line: int | None,
) -> None:
    """Every column one length, finite, plausible, and a flight's within its range."""
    n = len(columns["time_s"])
    for name, values in columns.items():
        if values.ndim != 1 or len(values) != n:
            raise RecordingError(
                path, header_line, f"column {name!r} has {len(values)} samples, time_s has {n}"
            )
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            i = int(bad[0])
            raise RecordingError(
                path, _where(lines, i), f"{_sample(lines, i)}{name} is {values[i]} (not finite)"
            )
        limit = MAX_ABS[name]
        bad = np.flatnonzero(np.abs(values) > limit)
        if bad.size:
            i = int(bad[0])
            raise RecordingError(
                path,
                _where(lines, i),
                f"{_sample(lines, i)}{name} is {values[i]:g}: implausible (beyond ±{limit:g}); "
                "refused rather than fitted",
            )
        if name in FLIGHT_RANGES:
            low, high = FLIGHT_RANGES[name]
            bad = np.flatnonzero((values < low) | (values > high))
            if bad.size:
                i = int(bad[0])
                raise RecordingError(
                    path,
                    _where(lines, i),
                    f"{_sample(lines, i)}{name} is {values[i]:g}: outside [{low:g}, {high:g}]"
                    + _descent_hint(name, values, columns["time_s"], i),
                )


def _check_sampling(
    time: FloatArray, path: str, lines: NDArray[np.int64] | None, time_read: str
) -> FloatArray:
    """Times strictly increasing, in seconds and evenly spaced; the intervals."""
    dt = np.diff(time)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise RecordingError(
            path,
            _where(lines, i),
            f"{_sample(lines, i)}time_s is not strictly increasing: "
            f"{time[i]:g} s follows {time[i - 1]:g} s",
        )
    median = float(np.median(dt))
    _check_time_scale(path, time_read, median, float(time[-1] - time[0]))
    deviation = np.abs(dt - median) / median
    bad = np.flatnonzero(deviation > SAMPLING_RTOL)
    if bad.size:
        i = int(bad[0]) + 1
        raise RecordingError(
            path,
            _where(lines, i),
            f"{_sample(lines, i)}irregular sampling: interval {dt[i - 1]:g} s "
            f"(from {time[i - 1]:g} s to {time[i]:g} s) differs from the median interval "
            f"{median:g} s by more than {SAMPLING_RTOL:.0%}",
        )

    return dt


def validate_samples(
    columns: Mapping[str, FloatArray],
    *,
    path: str = "<recording>",
    lines: NDArray[np.int64] | None = None,
    header_line: int | None = None,
    source: str | None = None,
    version: str | None = None,
    time_read: str = "time_s",
) -> None:
    """Check the sample columns of a recording; raise :class:`RecordingError`.

    Parameters
    ----------
    columns : mapping of str to ndarray
        Column name (from :data:`COLUMNS`) to 1-D float array, all one length.
    path : str
        File named in error messages.
    lines : ndarray of int, optional
        1-based file line of each sample, for error messages.  Without it,
        messages name the sample index.
    header_line : int, optional
        Line of the header, for column-level problems.
    source : str, optional
        The recording's source; ``ud_true_deg`` needs ``"synthetic"``.
    version : str, optional
        The file's declared format; the flight columns need :data:`FORMAT`.
    time_read : str
        How the times were read, for messages about their unit (an importer:
        its time column and the unit it was read in).
    """
    _check_column_set(columns, path, header_line, source, version)
    n = len(columns["time_s"])
    _check_values(columns, path, lines, header_line)
    if n < MIN_SAMPLES:
        raise RecordingError(
            path, None, f"too few samples: {n} (at least {MIN_SAMPLES} are needed)"
        )

    time = columns["time_s"]
    dt = _check_sampling(time, path, lines, time_read)

    if "roll_deg" in columns:
        jump = np.abs(np.diff(columns["roll_deg"])) / dt
        bad = np.flatnonzero(jump > MAX_RATE_DPS)
        if bad.size:
            i = int(bad[0]) + 1
            angle = columns["roll_deg"]
            raise RecordingError(
                path,
                _where(lines, i),
                f"{_sample(lines, i)}roll_deg jumps from {angle[i - 1]:g}° to {angle[i]:g}° in "
                f"{dt[i - 1]:g} s: implausible (a roll rate above {MAX_RATE_DPS:g} °/s); refused "
                "rather than fitted",
            )

    fins = [c for c in FIN_COLUMNS if c in columns]
    if all(np.ptp(columns[c]) < MIN_FIN_CHANGE_DEG for c in fins):
        raise RecordingError(
            path,
            None,
            f"the fin angle ({', '.join(fins)}) never changes by {MIN_FIN_CHANGE_DEG}° or more: "
            "nothing to identify",
        )


def _seconds(value: float) -> str:
    """``value`` s as a person would say it."""
    if value < 1.0:
        return f"{value * 1e3:g} ms"
    if value < 3600.0:
        return f"{value:g} s"
    return f"{value / 3600.0:.3g} h"


def _check_time_scale(path: str, time_read: str, interval: float, duration: float) -> None:
    """Refuse a sampling interval or a duration no roll log has: a time column in the wrong
    unit, most likely, whose identification would run away."""
    (low, high), (shortest, longest) = INTERVAL_RANGE_S, DURATION_RANGE_S
    # A 1 kHz log's times, written in decimal seconds, step 0.000999... s on the median.
    low, high = low * (1.0 - SAMPLING_RTOL), high * (1.0 + SAMPLING_RTOL)

    def plausible(scale: float) -> bool:
        return low <= interval * scale <= high and shortest <= duration * scale <= longest

    if plausible(1.0):
        return
    if not low <= interval <= high:
        found = f"{time_read} steps every {_seconds(interval)} (median), outside "
        found += f"{_seconds(INTERVAL_RANGE_S[0])} to {_seconds(INTERVAL_RANGE_S[1])}"
    else:
        found = f"{time_read} spans {_seconds(duration)}, outside "
        found += f"{_seconds(shortest)} to {_seconds(longest)}"
    if plausible(1e-3):
        hint = "is the time in milliseconds? (rocketroll import-csv --time-unit ms)"
    elif plausible(1e-6):
        hint = "is the time in microseconds? (rocketroll import-csv --time-unit us)"
    else:
        hint = "a roll log is sampled at 1 Hz to 1 kHz for 5 s to a day"
    raise RecordingError(path, None, f"{found}; {hint}")


def _has_line_break(text: str) -> bool:
    """True if ``text`` holds any character ``str.splitlines`` breaks at."""
    return bool(text) and text.splitlines() != [text]


#: Metadata keys holding text; every other ``truth.*`` and ``sensor.*`` value is a number.
TEXT_KEYS = frozenset({"truth.model", "truth.turbulence"})


def metadata_problem(key: str, value: str) -> str | None:
    """What is wrong with a typed metadata value, or None.

    ``seed`` is a non-negative integer; ``split`` is ``train`` or ``test``;
    ``truth.*`` and ``sensor.*`` values (but :data:`TEXT_KEYS`) are finite numbers.
    Other keys are free text.
    """
    if key == "split" and value not in ("train", "test"):
        return f"metadata 'split' must be 'train' or 'test', not {value!r}"
    if key == "seed" and not (value.isascii() and value.isdigit()):
        return f"metadata 'seed' must be a non-negative integer, not {value!r}"
    if key.startswith("rig.") and key not in RIG_METADATA:
        return f"unknown rig metadata {key!r}; known: {', '.join(RIG_METADATA)}"
    if key in LOOP_METADATA:
        try:
            number = parse_number(value)
        except ValueError:
            return f"metadata {key!r} must be a number, not {value!r}"
        bounds = LOOP_METADATA[key]
        if bounds is None:  # the gain: either sign, a loop only where it is not 0
            if not math.isfinite(number) or number == 0.0:
                return f"metadata {key!r} must be a finite number other than 0, not {value!r}"
        elif not bounds[0] <= number <= bounds[1] or (key == "loop.stops_deg" and number == 0):
            shown = f"({bounds[0]:g}" if key == "loop.stops_deg" else f"[{bounds[0]:g}"
            return f"metadata {key!r} must be in {shown}, {bounds[1]:g}], not {value!r}"
    if key.startswith(("truth.", "sensor.", "rig.")) and key not in TEXT_KEYS:
        try:
            number = parse_number(value)
        except ValueError:
            return f"metadata {key!r} must be a number, not {value!r}"
        if not math.isfinite(number):
            return f"metadata {key!r} must be finite, not {value!r}"
        most = RIG_METADATA.get(key)
        if key == FIN_RANGE_KEY and not 0.0 < number <= MAX_FIN_RANGE_DEG:
            return f"metadata {key!r} must be in (0, {MAX_FIN_RANGE_DEG:g}], not {value!r}"
        if most is not None and not 0.0 <= number <= most:
            return f"metadata {key!r} must be in [0, {most:g}], not {value!r}"
    return None


def _readonly(values: ArrayLike | None) -> FloatArray | None:
    return None if values is None else readonly_array(values)


@dataclass(frozen=True, eq=False)
class Recording:
    """A validated roll recording (format v1).

    Attributes
    ----------
    name : str
        Short identifier.
    source : str
        ``synthetic`` (virtual tunnel), ``wind-tunnel`` or ``flight``.
    time_s : ndarray, shape (n,)
        Sample times, s, uniform.
    fin_cmd_deg, fin_deg : ndarray or None
        Commanded / measured fin angle, °.
    roll_deg, roll_rate_dps : ndarray or None
        Encoder roll angle, ° / gyro roll rate, °/s.
    airspeed_mps, altitude_m : ndarray or None
        A flight's airspeed, m/s, and altitude above sea level, m (format 1.1).
    ud_true_deg : ndarray or None
        Ground-truth disturbance of a synthetic recording, ° (held over each
        sample interval).  Never an input to identification.
    metadata : mapping of str to str
        Every other ``# key: value`` line, in file order.

    Arrays are read-only.  Construction validates (:func:`validate_samples`).
    """

    name: str
    source: str
    time_s: FloatArray
    fin_cmd_deg: FloatArray | None = None
    fin_deg: FloatArray | None = None
    roll_deg: FloatArray | None = None
    roll_rate_dps: FloatArray | None = None
    airspeed_mps: FloatArray | None = None
    altitude_m: FloatArray | None = None
    ud_true_deg: FloatArray | None = None
    metadata: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        # The file format trims whitespace around values and cannot hold line breaks
        # of any kind (str.splitlines splits on \r, \u2028, ... as well as \n).
        name = self.name.strip()
        if not name or _has_line_break(name):
            raise RecordingError("<recording>", None, f"invalid name {self.name!r}")
        object.__setattr__(self, "name", name)
        if self.source not in SOURCES:
            raise RecordingError(
                "<recording>",
                None,
                f"source must be one of {', '.join(SOURCES)}, not {self.source!r}",
            )
        meta = {key: str(value).strip() for key, value in self.metadata.items()}
        for key, value in meta.items():
            if not _KEY.match(key) or key in _RESERVED:
                raise RecordingError("<recording>", None, f"invalid metadata key {key!r}")
            if _has_line_break(value):
                raise RecordingError("<recording>", None, f"metadata {key!r} spans lines")
            problem = metadata_problem(key, value)
            if problem:
                raise RecordingError("<recording>", None, problem)
        object.__setattr__(self, "metadata", MappingProxyType(meta))
        for column in COLUMNS:
            object.__setattr__(self, column, _readonly(getattr(self, column)))
        validate_samples(self.columns(), source=self.source)

    def columns(self) -> dict[str, FloatArray]:
        """The present sample columns, in :data:`COLUMNS` order."""
        out: dict[str, FloatArray] = {}
        for column in COLUMNS:
            values = getattr(self, column)
            if values is not None:
                out[column] = values
        return out

    @property
    def format(self) -> str:
        """The format the file is written in: :data:`FORMAT_V1_2` with a rig's description,
        else :data:`FORMAT` with flight columns, else :data:`FORMAT_V1`."""
        if any(key in self.metadata for key in RIG_METADATA):
            return FORMAT_V1_2
        return FORMAT_V1 if self.airspeed_mps is None else FORMAT

    @property
    def rig(self) -> Rig:
        """The rig the recording states (its ``rig.*`` lines; all 0 where it states none)."""
        return Rig.resolved({}, self.metadata)

    def rig_with(self, stated: StatedRig) -> Rig:
        """The rig with what ``stated`` gives, the recording's own lines for the rest."""
        return Rig.resolved(
            {f.name: getattr(stated, f.name) for f in fields(stated)}, self.metadata
        )

    def fin_range(self, stated: float | None = None) -> FinRange:
        """The fins' range: ``stated`` (a flag), else the recording's ``rig.fin_range_deg``
        line (both :attr:`FinRange.STATED`); else, for a synthetic recording, its virtual
        instrument's servo (:attr:`FinRange.TRUTH`: the tunnel's ``truth.fin_range_deg``, the
        flight recorder's eq. 23 servo, which its ``truth.servo_rate_dps`` line names); else
        the log's largest ``|fin|``, of the measured fin column if there is one, else of the
        command (:attr:`FinRange.LARGEST`).  Never a default the log does not show."""
        if stated is None and FIN_RANGE_KEY in self.metadata:
            stated = float(self.metadata[FIN_RANGE_KEY])
        if stated is not None:
            return FinRange(float(stated), FinRange.STATED)
        if self.source == "synthetic":
            if "truth.fin_range_deg" in self.metadata:
                return FinRange(float(self.metadata["truth.fin_range_deg"]), FinRange.TRUTH)
            if "truth.servo_rate_dps" in self.metadata:
                return FinRange(Servo().range_deg, FinRange.TRUTH)
        fin = self.fin_deg if self.fin_deg is not None else self.fin_cmd_deg
        return FinRange(float(np.max(np.abs(np.asarray(fin)))), FinRange.LARGEST)

    def stating_fin_range(self, deg: float | None) -> Recording:
        """The recording with ``rig.fin_range_deg`` set to ``deg`` (itself where None)."""
        if deg is None:
            return self
        columns = self.columns()
        return Recording(
            name=self.name,
            source=self.source,
            metadata={**self.metadata, FIN_RANGE_KEY: repr(float(deg))},
            **columns,
        )

    @property
    def loop(self) -> StatedLoop | None:
        """The rate loop the recording's ``loop.*`` lines state (None where they state none)."""
        return StatedLoop.of(self.metadata)

    def stating_loop(self, loop: StatedLoop | None) -> Recording:
        """The recording with ``loop``'s ``loop.*`` lines over its own (itself where None)."""
        if loop is None:
            return self
        return Recording(
            name=self.name,
            source=self.source,
            metadata={**self.metadata, **loop.metadata()},
            **self.columns(),
        )

    @property
    def is_flight(self) -> bool:
        """Whether the recording is a flight: its airspeed changes (1st to 99th percentile,
        so that a sensor's noise does not count) by more than :data:`STEADY_AIRSPEED_RTOL`
        of its median, so the roll model's gain and damping
        change along it.  A tunnel run that logs its steady airspeed is not one (the
        tunnel's methods identify it at that airspeed; the ``flight`` method may too)."""
        if self.airspeed_mps is None:
            return False
        low, middle, high = np.percentile(self.airspeed_mps, [1.0, 50.0, 99.0])
        return float(high - low) > STEADY_AIRSPEED_RTOL * float(middle)

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return int(self.time_s.size)

    @property
    def dt_s(self) -> float:
        """Sampling interval (median), s."""
        return float(np.median(np.diff(self.time_s)))

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample, s."""
        return float(self.time_s[-1] - self.time_s[0])

    @property
    def seed(self) -> int | None:
        """The tunnel seed of a synthetic recording, if recorded."""
        value = self.metadata.get("seed")
        return None if value is None else int(value)

    def truth(self) -> RollParams | None:
        """Ground-truth roll parameters recorded by the virtual tunnel, if any."""
        keys = ("truth.alpha", "truth.theta_bar_deg", "truth.beta_bar_per_s")
        if not all(k in self.metadata for k in keys):
            return None
        return RollParams(
            alpha=float(self.metadata["truth.alpha"]),
            theta_bar_deg=float(self.metadata["truth.theta_bar_deg"]),
            beta_bar_per_s=float(self.metadata["truth.beta_bar_per_s"]),
            alpha_bar_per_deg_s=float(self.metadata.get("truth.alpha_bar_per_deg_s", "0")),
        )

    def part(self, start_s: float, end_s: float, **metadata: str) -> Recording:
        """The samples at ``start_s <= t < end_s`` as a recording of their own (same name,
        source and sample times), with ``metadata`` added to its own.

        The split of one run into the part a controller is designed on and the part it is
        evaluated on (:func:`disturbances.ingest.holdout_rows`) is made with it.
        """
        keep = (self.time_s >= start_s) & (self.time_s < end_s)
        if int(np.count_nonzero(keep)) < 2:
            raise RecordingError(
                self.name, None, f"no samples between {start_s:g} and {end_s:g} s to keep"
            )
        columns = {name: values[keep] for name, values in self.columns().items()}
        return Recording(
            name=self.name,
            source=self.source,
            metadata={**self.metadata, **metadata},
            **columns,
        )

    def __repr__(self) -> str:
        cols = ",".join(c for c in self.columns() if c != "time_s")
        return (
            f"Recording(name={self.name!r}, source={self.source!r}, n={self.n_samples}, "
            f"dt={self.dt_s:g} s, duration={self.duration_s:g} s, columns=[{cols}])"
        )


def read_text(path: str | os.PathLike[str]) -> str:
    """A text file's contents, UTF-8 (a byte-order mark tolerated, as Excel writes it); a
    byte that is not UTF-8 is a :class:`RecordingError` naming its line."""
    name = os.fspath(path)
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise RecordingError(name, None, f"cannot read: {exc.strerror or exc}") from exc
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise RecordingError(
            name,
            line,
            f"byte 0x{data[exc.start]:02x} is not UTF-8 (a Latin-1 or Windows export?): save "
            "the file as UTF-8",
        ) from None


def _parse_metadata_line(path: str, lineno: int, text: str) -> tuple[str, str]:
    body = text[1:].strip()
    key, sep, value = body.partition(":")
    key = key.strip()
    if not sep or not _KEY.match(key):
        raise RecordingError(
            path, lineno, f"metadata line must read '# key: value', got {text.strip()!r}"
        )
    return key, value.strip()


def load_recording(path: str | os.PathLike[str]) -> Recording:
    """Read and validate a recording file (format v1).

    Parameters
    ----------
    path : str or path-like
        The CSV file.

    Returns
    -------
    Recording

    Raises
    ------
    RecordingError
        Naming the file, the line and the problem.
    """
    name = os.fspath(path)
    text = read_text(path)

    meta: dict[str, str] = {}
    meta_lines: dict[str, int] = {}
    header: list[str] | None = None
    header_line = 0
    rows: list[list[float]] = []
    row_lines: list[int] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if header is None:
            if line.startswith("#"):
                key, value = _parse_metadata_line(name, lineno, line)
                if key in meta:
                    raise RecordingError(
                        name,
                        lineno,
                        f"duplicate metadata key {key!r} (first on line {meta_lines[key]})",
                    )
                problem = metadata_problem(key, value)
                if problem:
                    raise RecordingError(name, lineno, problem)
                meta[key] = value
                meta_lines[key] = lineno
                continue
            header = [c.strip() for c in line.split(",")]
            header_line = lineno
            seen: set[str] = set()
            for column in header:
                if not column:
                    raise RecordingError(name, lineno, "empty column name (a stray comma?)")
                if column in seen:
                    raise RecordingError(name, lineno, f"duplicate column {column!r}")
                seen.add(column)
            continue
        if line.startswith("#"):
            raise RecordingError(name, lineno, "metadata lines must come before the header row")
        cells = line.split(",")
        if len(cells) != len(header):
            raise RecordingError(
                name, lineno, f"expected {len(header)} cells ({','.join(header)}), got {len(cells)}"
            )
        values: list[float] = []
        for column, cell in zip(header, cells, strict=True):
            try:
                number = parse_number(cell)
            except ValueError:
                raise RecordingError(
                    name, lineno, f"{column} is {cell.strip()!r}, not a number"
                ) from None
            if not math.isfinite(number):
                raise RecordingError(name, lineno, f"{column} is {cell.strip()} (not finite)")
            values.append(number)
        rows.append(values)
        row_lines.append(lineno)

    if header is None:
        raise RecordingError(name, None, "no header row (and no samples)")
    fmt = meta.pop("format", None)
    if fmt is not None and fmt not in FORMATS:
        raise RecordingError(
            name,
            meta_lines["format"],
            f"unsupported format {fmt!r}; this package reads {', '.join(FORMATS)}",
        )
    stated = [key for key in meta if key in RIG_METADATA]
    if stated and fmt is not None and fmt != FORMAT_V1_2:
        raise RecordingError(
            name,
            meta_lines[stated[0]],
            f"metadata {stated[0]!r} is format 1.2: the file must say '# format: "
            f"{FORMAT_V1_2}', not {fmt!r}",
        )
    source = meta.pop("source", None)
    if source is None:
        raise RecordingError(
            name, None, f"missing metadata '# source: ...' (one of {', '.join(SOURCES)})"
        )
    if source not in SOURCES:
        raise RecordingError(
            name,
            meta_lines["source"],
            f"source must be one of {', '.join(SOURCES)}, not {source!r}",
        )
    rec_name = meta.pop("name", "") or Path(name).stem

    data = np.array(rows, dtype=float).reshape(len(rows), len(header))
    columns = {column: data[:, j] for j, column in enumerate(header)}
    validate_samples(
        columns,
        path=name,
        lines=np.array(row_lines, dtype=np.int64),
        header_line=header_line,
        source=source,
        version=fmt,
    )
    try:
        return Recording(name=rec_name, source=source, metadata=meta, **columns)
    except RecordingError as exc:  # name/metadata problems found by the constructor
        raise RecordingError(name, None, exc.problem) from None


def format_number(x: float, decimals: int = 6) -> str:
    """Shortest fixed-point text with at most ``decimals`` decimals; deterministic."""
    text = f"{x:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def recording_text(recording: Recording) -> str:
    """The file contents :func:`save_recording` writes."""
    lines = [
        f"# format: {recording.format}",
        f"# name: {recording.name}",
        f"# source: {recording.source}",
    ]
    lines += [f"# {key}: {value}" for key, value in recording.metadata.items()]
    columns = recording.columns()
    lines.append(",".join(columns))
    table = np.column_stack(list(columns.values())).tolist()
    # Time gets nanoseconds so that even fast loggers stay uniformly sampled.
    lines += [
        ",".join([format_number(row[0], TIME_DECIMALS), *(format_number(x) for x in row[1:])])
        for row in table
    ]
    return "\n".join(lines) + "\n"


def save_recording(recording: Recording, path: str | os.PathLike[str]) -> None:
    """Write a recording in format v1 (1.1 with flight columns), atomically.

    Numbers are written in fixed point with at most 6 decimals (time with
    :data:`TIME_DECIMALS`), so the same recording always gives the same bytes.
    """
    write_atomic(path, recording_text(recording))


def metadata_items(pairs: Sequence[tuple[str, object]]) -> dict[str, str]:
    """Metadata dict from ``(key, value)`` pairs; floats as their shortest exact repr."""
    return {key: repr(value) if isinstance(value, float) else str(value) for key, value in pairs}
