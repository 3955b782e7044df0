"""Bring foreign roll data (a user's wind-tunnel log, a flight log) into format v1.

Example: a headerless file in radians, sampled at 100 Hz, whose two columns
are the measured fin angle and the encoder roll angle::

    rocketroll import-csv run.txt --out run.csv --columns fin,roll \\
        --no-header --units rad --rate 100

Errors name the *input* file and its line.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from identification.recordings.recording import (
    FIN_RANGE_KEY,
    PLAUSIBLE_FIN_DEG,
    LoopFlags,
    Recording,
    RecordingError,
    StatedRig,
    fin_range_setting,
    parse_number,
    read_text,
    small_fins,
    validate_samples,
)
from rocketroll_common.arrays import FloatArray
from rocketroll_common.errors import SettingError
from rocketroll_common.settings import check, check_order, setting

__all__ = ["ROLES", "ImportSettings", "angle_on_integrated_rate", "import_csv", "read_csv"]

#: Role of an input column -> the format-v1 column it becomes (None: ignored).
ROLES: dict[str, str | None] = {
    "time": "time_s",
    "fin_cmd": "fin_cmd_deg",
    "fin": "fin_deg",
    "roll": "roll_deg",
    "roll_rate": "roll_rate_dps",
    "airspeed": "airspeed_mps",
    "altitude": "altitude_m",
    "skip": None,
}
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6}
ANGLE_UNITS = {"deg": 1.0, "rad": 180.0 / np.pi}
#: Airspeed units (``--speed-unit``) in m/s.
SPEED_UNITS = {"mps": 1.0, "kmh": 1.0 / 3.6, "fps": 0.3048, "kn": 1852.0 / 3600.0}
#: Altitude units (``--altitude-unit``) in m.
ALTITUDE_UNITS = {"m": 1.0, "ft": 0.3048}


def _delimiter(text: str) -> str:
    """A ``--delimiter`` value: one character, with ``\\t`` (or ``tab``) for a tab."""
    named = {"tab": "\t", "\\t": "\t", "space": " ", "comma": ",", "semicolon": ";"}
    value = named.get(text.lower(), text)
    if len(value) != 1:
        raise argparse.ArgumentTypeError(
            f"--delimiter must be one character (or \\t, tab, space), not {text!r}"
        )
    return value


@dataclass(frozen=True)
class ImportSettings:
    """How a foreign delimited text file maps onto a recording (``rocketroll import-csv``)."""

    columns: tuple[str, ...] = setting(
        (),
        "comma-separated role of each input column: time, fin_cmd, fin, roll, roll_rate, "
        "airspeed, altitude (a flight: format 1.1), skip (required)",
        metavar="ROLES",
    )
    header: bool = setting(True, "the first non-comment line is a header row (--no-header: none)")
    units: Literal["deg", "rad"] = setting("deg", "unit of angles (and of the rate, per second)")
    rate_hz: float | None = setting(
        None, "sampling rate when no column holds time", flag="--rate", gt=0.0, le=1e7, unit="Hz"
    )
    time_column: str | None = setting(
        None, "the time column by header name (or 1-based number without header)"
    )
    time_unit: Literal["s", "ms", "us"] = setting("s", "unit of the time column")
    speed_unit: Literal["mps", "kmh", "fps", "kn"] = setting(
        "mps", "unit of an airspeed column: m/s, km/h, ft/s or knots"
    )
    altitude_unit: Literal["m", "ft"] = setting(
        "m", "unit of an altitude column (above sea level: it gives the ISA density)"
    )
    delimiter: str | None = setting(
        None,
        "cell separator (default: each line's comma, semicolon or tab, else whitespace)",
        parse=_delimiter,
    )
    unit: dict[str, Any] = setting(
        default_factory=dict,
        help="the unit of one column, over --units, --time-unit, --speed-unit and "
        "--altitude-unit, e.g. roll=rad (repeatable)",
        metavar="ROLE=UNIT",
    )
    scale: dict[str, Any] = setting(
        default_factory=dict,
        help="multiply a column by FACTOR after its unit, e.g. fin=-1 for a fin whose sign is "
        "the other way round (repeatable)",
        metavar="ROLE=FACTOR",
    )
    offset: dict[str, Any] = setting(
        default_factory=dict,
        help="add VALUE to a column after its unit and scale, in °, °/s, s, m/s or m, e.g. "
        "fin=-1.5 for a fin trimmed off zero (repeatable)",
        metavar="ROLE=VALUE",
    )
    time_from: float | None = setting(
        None, "keep the rows from this time on (the time column after its unit, scale and offset)",
        flag="--from", ge=-1e9, le=1e9, unit="s",
    )  # fmt: skip
    time_to: float | None = setting(
        None, "keep the rows up to this time", flag="--to", ge=-1e9, le=1e9, unit="s"
    )
    site_elevation: float = setting(
        0.0,
        "the site's elevation above sea level, added to an altitude column logged above the "
        "ground (the ISA density needs the altitude above sea level)",
        ge=-500.0, le=9000.0, unit="m",
    )  # fmt: skip
    unwrap: bool = setting(False, "unwrap a roll angle that wraps at 360°")
    name: str | None = setting(None, "recording name (default: the input file's stem)")
    source: Literal["wind-tunnel", "flight"] = setting(
        "wind-tunnel",
        "where the data come from (a synthetic recording, with its known truth, is written "
        "by rocketroll tunnel or flight, not imported)",
    )
    notes: str | None = setting(None, "free-text notes stored in the metadata")
    rig: StatedRig = setting(default_factory=StatedRig, flatten=True)
    loop: LoopFlags = setting(default_factory=LoopFlags, flatten=True)
    fin_range_deg: float | None = fin_range_setting(
        "your fins' range, ± this (where the canards stop), stored in the recording: "
        "identification measures u_d against it (unstated: the log's largest |fin|)"
    )
    split: Literal["train", "test"] | None = setting(
        None,
        "the database split the recording belongs to, stored in its metadata (default: "
        "chosen by its samples, a quarter of recordings test)",
    )

    def __post_init__(self) -> None:
        object.__setattr__(self, "columns", tuple(c.strip() for c in self.columns))
        check(self)
        if self.delimiter is not None and len(self.delimiter) != 1:
            raise SettingError("delimiter", f"must be one character, not {self.delimiter!r}")
        for field, given in (("unit", self.unit), ("scale", self.scale), ("offset", self.offset)):
            for role, value in given.items():
                timed = ("time",) if self.time_column is not None else ()
                _check_column_setting(field, role, value, (*self.columns, *timed))
        check_order("time_from", self.time_from, self.time_to, "--to", "s")
        if self.site_elevation and "altitude" not in self.columns:
            raise SettingError("site_elevation", "is added to an altitude column; give one")
        self.loop.stated(None, "an imported log")  # --loop-delay needs --loop-gain here

    def column_unit(self, role: str) -> float:
        """The factor that takes column ``role`` to the recording's unit: ``--unit ROLE=``,
        else its kind's flag (``--time-unit``, ``--speed-unit``, ``--altitude-unit``,
        ``--units`` for angles)."""
        kinds = {
            "time": self.time_unit,
            "airspeed": self.speed_unit,
            "altitude": self.altitude_unit,
        }
        default = kinds.get(role, self.units)
        return _units_of(role)[str(self.unit.get(role, default))]


#: Column role -> its units, by name, to the recording's (--unit ROLE=UNIT); angles else.
_UNIT_TABLES: dict[str, dict[str, float]] = {
    "time": TIME_UNITS,
    "airspeed": SPEED_UNITS,
    "altitude": ALTITUDE_UNITS,
}


def _units_of(role: str) -> dict[str, float]:
    """The units column ``role`` may be in (an angle's, or a rate's per second, by default)."""
    return _UNIT_TABLES.get(role, ANGLE_UNITS)


def _check_column_setting(field: str, role: str, value: Any, columns: tuple[str, ...]) -> None:
    """Refuse (``SettingError``) a ``--unit``/``--scale``/``--offset`` entry that names no
    column of ``--columns`` or gives a value that is not one."""
    if role not in columns or role == "skip":
        named = ", ".join(c for c in columns if c != "skip") or "none"
        raise SettingError(field, f"{role!r} is not a column of --columns ({named})")
    if field == "unit":
        table = _units_of(role)
        if value not in table:
            raise SettingError(
                field, f"{role}={value!r}: the units of {role} are {', '.join(table)}"
            )
        return
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise SettingError(field, f"{role}={value!r} is not a finite number")
    if field == "scale" and value == 0:
        raise SettingError(field, f"{role}=0 would erase the column")


def _cells(line: str, delimiter: str) -> list[str]:
    """The cells of one line (quotes as the csv module reads them), stripped."""
    if delimiter == " ":
        line = line.replace("\t", " ")
    row = next(csv.reader([line], delimiter=delimiter, skipinitialspace=True), [])
    return [c.strip() for c in row]


#: A number written with a decimal comma (``-1,25``, ``3,5e-2``), as semicolon exports do.
_DECIMAL_COMMA = re.compile(r"[+-]?\d+,\d*(?:[eE][+-]?\d+)?")


def _guess_delimiter(line: str) -> str:
    """The delimiter of a file whose first line is ``line``: a semicolon if it has one
    outside quotes (a decimal-comma export), else a tab, else a comma, else whitespace."""
    bare = re.sub(r'"[^"]*"', "", line)
    return next((d for d in (";", "\t", ",") if d in bare), " ")


def import_csv(
    path: str | os.PathLike[str],
    columns: Sequence[str],
    *,
    header: bool = True,
    units: str = "deg",
    rate_hz: float | None = None,
    time_column: str | None = None,
    time_unit: str = "s",
    delimiter: str | None = None,
    unwrap: bool = False,
    name: str | None = None,
    source: str = "wind-tunnel",
    notes: str | None = None,
    speed_unit: str = "mps",
    altitude_unit: str = "m",
) -> Recording:
    """Read a foreign delimited text file into a validated :class:`Recording`.

    Parameters
    ----------
    path : str or path-like
        Input file.  Blank lines and lines starting with ``#`` are skipped.
    columns : sequence of str
        One role per input column, from :data:`ROLES`: ``time``, ``fin_cmd``,
        ``fin``, ``roll``, ``roll_rate`` or ``skip``.
    header : bool
        Whether the first non-comment line is a header row (skipped, but its
        names can be used by ``time_column``).
    units : {"deg", "rad"}
        Unit of the angle columns (and rad/s or °/s for ``roll_rate``).
    rate_hz : float, optional
        Sampling rate when no column holds time; time starts at 0.
    time_column : str, optional
        The input column holding time: its header name, or its 1-based
        position in a headerless file.  Its ``columns`` entry must be
        ``time`` or ``skip``.
    time_unit : {"s", "ms", "us"}
        Unit of the time column.
    delimiter : str, optional
        Cell separator (one character); default: ``,`` ``;`` or tab if the
        first line has one, else whitespace.  Cells are read by the ``csv``
        module, so quoted cells (``csv.QUOTE_ALL``) are fine.
    unwrap : bool
        Unwrap a roll angle that wraps around (e.g. at ±180° or 0/360°).
    name, source, notes : str, optional
        Metadata of the new recording; ``name`` defaults to the file stem; ``source``
        is ``"wind-tunnel"`` or ``"flight"`` (an import is measured data: a synthetic
        recording carries its truth and comes from the virtual tunnel or flight).
    speed_unit : {"mps", "kmh", "fps", "kn"}
        Unit of an ``airspeed`` column (a flight; the recording is then format 1.1).
    altitude_unit : {"m", "ft"}
        Unit of an ``altitude`` column (above sea level).

    Returns
    -------
    Recording

    Raises
    ------
    RecordingError
        Naming the input file, the line and the problem.
    """
    try:
        settings = ImportSettings(
            columns=tuple(columns),
            header=header,
            units=units,  # type: ignore[arg-type]
            rate_hz=rate_hz,
            time_column=time_column,
            time_unit=time_unit,  # type: ignore[arg-type]
            delimiter=delimiter,
            unwrap=unwrap,
            name=name,
            source=source,  # type: ignore[arg-type]
            notes=notes,
            speed_unit=speed_unit,  # type: ignore[arg-type]
            altitude_unit=altitude_unit,  # type: ignore[arg-type]
        )
    except SettingError as exc:
        raise RecordingError(os.fspath(path), None, f"{exc.setting}: {exc.problem}") from None
    return read_csv(path, settings)


def _converted(
    data: FloatArray, roles: list[str], settings: ImportSettings, index: int | None
) -> dict[str, FloatArray]:
    """The read columns in the recording's units (``index``: the time column's; None: times
    from ``--rate``), scaled, offset, the altitude above sea level, the angle unwrapped."""
    out: dict[str, FloatArray] = {}
    if index is None:
        assert settings.rate_hz is not None
        out["time_s"] = np.arange(data.shape[0]) / settings.rate_hz
    else:
        out["time_s"] = data[:, index] * settings.column_unit("time")
    for j, role in enumerate(roles):
        target = ROLES[role]
        if target is not None and target != "time_s":
            out[target] = data[:, j] * settings.column_unit(role)
    timed = ["time"] if index is not None else []  # a time column, by role or by name
    for role in {*roles, *timed}:
        target = ROLES[role]
        if target is not None and (role in settings.scale or role in settings.offset):
            out[target] = out[target] * settings.scale.get(role, 1.0) + settings.offset.get(
                role, 0.0
            )
    if settings.site_elevation and "altitude_m" in out:
        out["altitude_m"] = out["altitude_m"] + settings.site_elevation
    if settings.unwrap and "roll_deg" in out:
        out["roll_deg"] = np.unwrap(out["roll_deg"], period=360.0)
    return out


def _import_metadata(
    where: str, roles: list[str], settings: ImportSettings, out: dict[str, FloatArray]
) -> dict[str, str]:
    """How a log was imported, as its recording's metadata (and the user's notes, rig and
    split)."""
    meta = {"imported_from": Path(where).name, "import.columns": ",".join(roles)}
    meta["import.units"] = settings.units
    for field in ("unit", "scale", "offset"):
        given = getattr(settings, field)
        if given:
            meta[f"import.{field}"] = ",".join(f"{k}={v}" for k, v in given.items())
    if settings.time_from is not None:
        meta["import.from_s"] = repr(settings.time_from)
    if settings.time_to is not None:
        meta["import.to_s"] = repr(settings.time_to)
    if "airspeed_mps" in out:
        meta["import.speed_unit"] = str(settings.unit.get("airspeed", settings.speed_unit))
    if "altitude_m" in out:
        meta["import.altitude_unit"] = str(settings.unit.get("altitude", settings.altitude_unit))
    if settings.site_elevation:
        meta["import.site_elevation_m"] = repr(settings.site_elevation)
    if settings.notes:
        meta["notes"] = settings.notes
    meta.update(settings.rig.metadata())  # what the user states of the rig (format 1.2)
    loop = settings.loop.stated(None, "an imported log")  # and of the flight computer's loop
    if loop is not None:
        meta.update(loop.metadata())
    if settings.fin_range_deg is not None:
        meta[FIN_RANGE_KEY] = repr(float(settings.fin_range_deg))
    if settings.split is not None:
        meta["split"] = settings.split
    return meta


def read_csv(path: str | os.PathLike[str], settings: ImportSettings) -> Recording:
    """:func:`import_csv` with its settings as one :class:`ImportSettings`."""
    where = os.fspath(path)
    roles = list(settings.columns)
    header, rate_hz = settings.header, settings.rate_hz
    time_column, time_unit, delimiter = settings.time_column, settings.time_unit, settings.delimiter
    if not roles:
        raise RecordingError(where, None, "--columns is empty: give one role per input column")
    for role in roles:
        if role not in ROLES:
            raise RecordingError(
                where, None, f"unknown column role {role!r} in --columns; use {', '.join(ROLES)}"
            )
    for role in set(roles) - {"skip"}:
        if roles.count(role) > 1:
            raise RecordingError(where, None, f"column role {role!r} appears more than once")
    # A 'time' role names the time column; --time-column may name the same column.
    time_role = "time" in roles and time_column is None
    time_sources = time_role + (rate_hz is not None) + (time_column is not None)
    if time_sources != 1:
        raise RecordingError(
            where,
            None,
            "give time exactly one way: a 'time' entry in --columns, --rate HZ, "
            "or --time-column NAME",
        )

    text = read_text(path)

    names: list[str] | None = None
    header_line: int | None = None
    rows: list[list[float]] = []
    lines: list[int] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        if delimiter is None:  # without --delimiter, the first line's, for every line
            delimiter = _guess_delimiter(line)
        try:
            cells = _cells(line, delimiter)
        except csv.Error as exc:
            raise RecordingError(where, lineno, f"unreadable cells ({exc})") from None
        if len(cells) != len(roles):
            raise RecordingError(
                where,
                lineno,
                f"{len(cells)} cells but --columns names {len(roles)} ({','.join(roles)})",
            )
        if header and names is None:
            names, header_line = cells, lineno
            continue
        row: list[float] = []
        for role, cell in zip(roles, cells, strict=True):
            if role == "skip" and time_column is None:
                row.append(0.0)
                continue
            if delimiter == ";" and _DECIMAL_COMMA.fullmatch(cell.strip()):
                cell = cell.replace(",", ".")  # a semicolon export's decimal comma
            try:
                row.append(parse_number(cell))
            except ValueError:
                if role == "skip":  # a skipped column need not be numeric
                    row.append(np.nan)
                    continue
                raise RecordingError(where, lineno, f"{role} is {cell!r}, not a number") from None
        rows.append(row)
        lines.append(lineno)
    if not rows:
        raise RecordingError(where, None, "no data rows")

    data = np.array(rows, dtype=float)
    index = None
    if rate_hz is None:
        index = (
            roles.index("time")
            if time_column is None
            else _time_index(where, time_column, names, roles, header_line)
        )
    # A value that overflows in its unit's conversion (1e308 rad) becomes inf, which the
    # validation below refuses, naming its line.
    with np.errstate(over="ignore", invalid="ignore"):
        out = _converted(data, roles, settings, index)
    kept = np.asarray(lines, dtype=np.int64)
    if settings.time_from is not None or settings.time_to is not None:
        out, kept = _window(where, out, kept, settings.time_from, settings.time_to)

    if index is None:
        time_read = f"--rate {rate_hz:g} Hz"
    else:
        label = names[index] if names is not None else f"column {index + 1}"
        time_read = f"the time column ({label!r}, read in {settings.unit.get('time', time_unit)})"
    validate_samples(
        out,
        path=where,
        lines=kept,
        header_line=header_line,
        time_read=time_read,
    )
    _check_rate_unit(where, out, settings)
    meta = _import_metadata(where, roles, settings, out)
    return Recording(
        name=settings.name or Path(where).stem, source=settings.source, metadata=meta, **out
    )


#: Degrees per radian: a rate column in the wrong angular unit is off by this factor.
_RAD = 180.0 / math.pi
#: The roll angle against the integrated rate column (a least-squares slope) within this
#: fraction of ``_RAD`` or 1/``_RAD`` is a rate (or an angle) in the other unit; judged only
#: where the fit is tight (R² at least ``_UNIT_R2``): the angle moves enough to tell.
_UNIT_BAND, _UNIT_R2 = 0.15, 0.9


def angle_on_integrated_rate(
    time: FloatArray, angle: FloatArray, rate: FloatArray
) -> tuple[float, float]:
    """How the roll angle follows the integrated roll rate: the least-squares slope of the
    angle on the rate's running integral (trapezoids) and its R², 1 where both are in the
    same unit, 57.3 or 1/57.3 where one is in radians and the other in degrees.

    Robust to what a log does: an angle that wraps (at ±180° or 0/360°, or at ±π in
    radians: unwrapped first, the unwrapping that fits best kept), a gyro's bias (the fit
    also takes a line in time, whose drift it absorbs, and, where the angle itself moves
    along that line, without it) and noise (integrated, not differentiated).  (NaN, NaN)
    where the rate does not move the angle at all."""
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(time))])
    best = (math.nan, math.nan)
    if not np.ptp(integral) > 0.0:
        return best
    angles = [np.unwrap(angle, period=360.0)]
    if float(np.max(np.abs(angle))) <= 2.0 * math.pi * 1.001:  # an angle in radians, wrapped
        angles.append(np.unwrap(angle, period=2.0 * math.pi))
    ones = np.ones(time.size)
    span = max(float(time[-1] - time[0]), 1e-300)
    line = (time - time[0]) / span
    for x in (np.column_stack([ones, line, integral]), np.column_stack([ones, integral])):
        for y in angles:
            coef, *_ = np.linalg.lstsq(x, y, rcond=None)
            # R² of the part the integrated rate explains, beyond the other columns.
            base, *_ = np.linalg.lstsq(x[:, :-1], y, rcond=None)
            left = y - x[:, :-1] @ base
            total = float(left @ left)
            residual = y - x @ coef
            if not total > 0.0:
                continue
            r2 = 1.0 - float(residual @ residual) / total
            if not r2 <= best[1]:  # the first, or a better fit (NaN compares false)
                best = (float(coef[-1]), r2)
    return best


def _check_rate_unit(where: str, out: dict[str, FloatArray], settings: ImportSettings) -> None:
    """Refuse a roll rate in another angular unit than the roll angle beside it (rad/s read
    as °/s looks plausible on its own: 2.6 °/s): the angle against the integrated rate
    (:func:`angle_on_integrated_rate`) is 1 when they agree and 57.3 or 1/57.3 when one is
    in radians; the message names the ``--unit`` that fits."""
    if "roll_deg" not in out or "roll_rate_dps" not in out:
        return
    time, angle, rate = out["time_s"], out["roll_deg"], out["roll_rate_dps"]
    if time.size < 3 or not np.all(np.diff(time) > 0):
        return  # the recording's own validation names it
    slope, r2 = angle_on_integrated_rate(time, angle, rate)
    if not r2 >= _UNIT_R2:
        return  # the angle does not follow the rate closely enough to say
    read_angle = str(settings.unit.get("roll", settings.units))
    read_rate = str(settings.unit.get("roll_rate", settings.units))
    both = f"roll angle read in {read_angle}, roll_rate in {read_rate}/s"
    if abs(slope / _RAD - 1.0) <= _UNIT_BAND:  # the angle is 57 times the integrated rate
        fixes = ["roll_rate=rad"] * (read_rate == "deg") + ["roll=deg"] * (read_angle == "rad")
        said = "the rate looks like rad/s" if read_rate == "deg" else "the angle looks like °"
        raise RecordingError(
            where,
            None,
            f"the roll angle changes {slope:.3g} times as fast as the roll_rate column says "
            f"({both}): {said}; give " + " or ".join(f"--unit {f}" for f in fixes),
        )
    if abs(slope * _RAD - 1.0) <= _UNIT_BAND:  # the integrated rate is 57 times the angle
        fixes = ["roll_rate=deg"] * (read_rate == "rad") + ["roll=rad"] * (read_angle == "deg")
        said = "the rate looks like °/s" if read_rate == "rad" else "the angle looks like rad"
        raise RecordingError(
            where,
            None,
            f"the roll_rate column is {1.0 / slope:.3g} times the roll angle's rate of change "
            f"({both}): {said}; give " + " or ".join(f"--unit {f}" for f in fixes),
        )


#: A flight's roll rate whose 99th percentile of ``|rate|`` stays below this, °/s, is
#: implausibly small for a rocket in flight (a rad/s column read as °/s reads 57 times small).
PLAUSIBLE_FLIGHT_RATE_DPS = 5.0


def plausibility_warnings(recording: Recording) -> list[str]:
    """What looks wrong in an imported recording without being certain, one line each:

    * a fin column whose 99th percentile of ``|value|`` stays under
      :data:`~identification.recordings.recording.PLAUSIBLE_FIN_DEG` (a fin in radians read as
      degrees: ±10° reads ±0.17), named by its role and input column (the recording's
      ``import.*`` metadata), with the ``--unit`` that fits if it was read in degrees;
    * a flight whose roll rate stays below :data:`PLAUSIBLE_FLIGHT_RATE_DPS` all along
      (where no angle beside it lets the unit be checked, :func:`read_csv` refuses a rate
      that disagrees with one).
    """
    found = []
    meta = recording.metadata
    roles = meta.get("import.columns", "").split(",")
    given = dict(e.split("=", 1) for e in meta.get("import.unit", "").split(",") if "=" in e)
    for name, p99 in small_fins(recording.columns()).items():
        role = next(r for r, target in ROLES.items() if target == name)
        where = f"{role} (column {roles.index(role) + 1})" if role in roles else name
        read = given.get(role, meta.get("import.units", "deg"))
        fix = (
            f"radians read as degrees? give --unit {role}=rad"
            if read == "deg"
            else "check its unit"
        )
        found.append(
            f"{where}: 99 % of its |values| are under {p99:.2g}°, implausibly small for a fin "
            f"(under {PLAUSIBLE_FIN_DEG:g}°): {fix}"
        )
    rate = recording.roll_rate_dps
    if recording.airspeed_mps is None or rate is None or recording.roll_deg is not None:
        return found
    p99 = float(np.percentile(np.abs(rate), 99.0))
    if p99 >= PLAUSIBLE_FLIGHT_RATE_DPS:
        return found
    return [
        *found,
        f"the roll rate stays within {p99:.3g} °/s (99th percentile) all flight: small for a "
        f"rocket in flight (under {PLAUSIBLE_FLIGHT_RATE_DPS:g} °/s); a column in rad/s read as "
        "°/s looks like this (--unit roll_rate=rad if so)",
    ]


def _window(
    where: str,
    columns: dict[str, FloatArray],
    lines: np.ndarray,
    start: float | None,
    stop: float | None,
) -> tuple[dict[str, FloatArray], np.ndarray]:
    """The rows whose time lies in [``start``, ``stop``] (``--from``/``--to``)."""
    t = columns["time_s"]
    keep = np.ones(t.size, dtype=bool)
    if start is not None:
        keep &= t >= start
    if stop is not None:
        keep &= t <= stop
    keep |= ~np.isfinite(t)  # kept for the validation to name its line
    if not keep[np.isfinite(t)].any():
        finite = t[np.isfinite(t)]
        span = f"{finite.min():g} to {finite.max():g} s" if finite.size else "no finite times"
        raise RecordingError(where, None, f"--from/--to keep no rows: the time column runs {span}")
    return {name: values[keep] for name, values in columns.items()}, lines[keep]


def _time_index(
    where: str, time_column: str, names: list[str] | None, roles: list[str], header_line: int | None
) -> int:
    if names is not None:
        if time_column not in names:
            raise RecordingError(
                where,
                header_line,
                f"--time-column {time_column!r} is not in the header ({', '.join(names)})",
            )
        index = names.index(time_column)
    else:
        try:
            index = int(time_column) - 1
        except ValueError:
            raise RecordingError(
                where,
                None,
                f"--time-column {time_column!r}: without a header, give the 1-based column number",
            ) from None
        if not 0 <= index < len(roles):
            raise RecordingError(
                where, None, f"--time-column {time_column} is outside columns 1..{len(roles)}"
            )
    if roles[index] not in ("time", "skip"):
        raise RecordingError(
            where,
            None,
            f"--time-column {time_column!r} is also given the role {roles[index]!r} in --columns",
        )
    return index
