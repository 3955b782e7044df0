"""``rocketroll`` commands of the identification layer: ``tunnel`` and ``record-flight``
(the virtual tunnel and flight recorder), ``import-csv``, ``info``.

Each command is a settings dataclass (its options, with help, defaults and
bounds on the fields) and a function; :mod:`rocketroll_common.settings`
makes the parser, and the ``rocketroll`` command line
(:mod:`rocketroll.cli`) finds them in :data:`COMMANDS`.  No library module
imports this one.
"""

from __future__ import annotations

import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path

from identification.instruments.flightlog import FlightLogSpec
from identification.instruments.tunnel import TunnelSpec
from identification.recordings.importer import ImportSettings
from rocketroll_common.errors import UsageError
from rocketroll_common.settings import Command, check, setting

__all__ = ["COMMANDS", "ImportArgs", "InfoArgs", "RecordFlightArgs", "TunnelArgs"]


@dataclass(frozen=True)
class TunnelArgs:
    """``rocketroll tunnel``."""

    out: Path = setting(help="recording file to write (CSV)", output="file", kind="recording")
    spec: TunnelSpec = setting(default_factory=TunnelSpec, flatten=True)


def tunnel(args: TunnelArgs) -> int:
    """Run the virtual tunnel and write the recording."""
    from identification.instruments.tunnel import run_tunnel
    from identification.recordings.recording import save_recording

    recording = run_tunnel(args.spec)
    save_recording(recording, args.out)
    print(f"wrote {args.out}: {recording!r}")
    return 0


@dataclass(frozen=True)
class RecordFlightArgs:
    """``rocketroll record-flight``."""

    out: Path = setting(
        help="recording file to write (CSV, format 1.1)", output="file", kind="recording"
    )
    spec: FlightLogSpec = setting(default_factory=FlightLogSpec, flatten=True)


def record_flight(args: RecordFlightArgs) -> int:
    """Fly the virtual flight recorder and write its log."""
    from identification.instruments.flightlog import AscentError, run_flight
    from identification.recordings.recording import save_recording

    try:
        recording = run_flight(args.spec)
    except AscentError as exc:
        raise UsageError(f"--ascent {args.spec.ascent}: {exc}") from None
    save_recording(recording, args.out)
    print(f"wrote {args.out}: {recording!r}")
    return 0


@dataclass(frozen=True)
class InfoArgs:
    """``rocketroll info``."""

    recording: Path = setting(help="recording file (CSV, format v1)", positional=True, input=True)
    json: Path | None = setting(
        None, "also write the summary as JSON here", output="file", kind="json"
    )
    plot: Path | None = setting(
        None, "also write a PNG figure (like the paper's Fig. 2)", output="file", kind="png"
    )

    def __post_init__(self) -> None:
        check(self)


def info(args: InfoArgs) -> int:
    """Validate a recording, print its summary, write the JSON and figure asked for."""
    from identification.recordings.recording import load_recording
    from identification.reports.summary import plot_recording, summarize
    from rocketroll_common.files import write_all_atomic

    recording = load_recording(args.recording)
    summary = summarize(recording)
    # Everything is computed before anything is written.
    outputs: dict[str | os.PathLike[str], str | bytes] = {}
    if args.json:
        outputs[args.json] = json.dumps(summary.to_dict(), indent=2) + "\n"
    if args.plot:
        outputs[args.plot] = plot_recording(recording)
    write_all_atomic(outputs)  # all or nothing
    print(summary.format())
    for path in outputs:
        print(f"wrote {path}")
    return 0


@dataclass(frozen=True)
class ImportArgs:
    """``rocketroll import-csv``."""

    input: Path = setting(help="input file", positional=True, input=True)
    out: Path = setting(help="recording file to write", output="file", kind="recording")
    settings: ImportSettings = setting(default_factory=ImportSettings, flatten=True)

    def __post_init__(self) -> None:
        if not self.settings.columns:
            raise UsageError("--columns is required: one role per input column")


def import_csv(args: ImportArgs) -> int:
    """Convert the file and write the recording."""
    from identification.recordings.importer import plausibility_warnings, read_csv
    from identification.recordings.recording import save_recording

    recording = read_csv(args.input, args.settings)
    save_recording(recording, args.out)
    print(f"wrote {args.out}: {recording!r}")
    for text in plausibility_warnings(recording):
        print(f"warning: {args.input}: {text}", file=sys.stderr)
    return 0


#: The commands of this layer, by name.
COMMANDS: dict[str, Command] = {
    "tunnel": Command(
        "tunnel",
        "run the virtual wind tunnel and write a synthetic recording",
        TunnelArgs,
        tunnel,
        "Re-create the paper's wind-tunnel experiment with known ground truth "
        "(defaults: the paper's parameters and Table 1 schedule).",
    ),
    "record-flight": Command(
        "record-flight",
        "fly the virtual flight recorder and write a synthetic flight log",
        RecordFlightArgs,
        record_flight,
        "The virtual tunnel's flight counterpart: the rocket (truth given at --v-ref) along "
        "an ascent from the rail to apogee, its gain and damping scaled by eq. 4-8, a fin "
        "staircase, flown turbulence, a rate gyro; a format-1.1 recording with the truth "
        "in its metadata.  Identify it with: rocketroll identify LOG.csv",
    ),
    "import-csv": Command(
        "import-csv",
        "convert a foreign CSV/text log into a recording",
        ImportArgs,
        import_csv,
        "Convert a delimited text file (a wind-tunnel or flight log) into a recording.\n"
        "Example: rocketroll import-csv run.txt --out run.csv --columns fin,roll --no-header "
        "--units rad --rate 100",
    ),
    "info": Command(
        "info",
        "validate a recording and print its summary",
        InfoArgs,
        info,
        "Validate a recording (format v1) and print a summary.",
    ),
}
