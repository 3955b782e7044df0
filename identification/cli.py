"""``rocketroll`` subcommands of the identification layer: tunnel, import-csv, info."""

from __future__ import annotations

import argparse
import json
import os
from collections.abc import Sequence
from dataclasses import fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

from identification.errors import UsageError

if TYPE_CHECKING:
    from identification.tunnel import TunnelSpec

__all__ = ["register", "tunnel_spec_from_argv"]

# Help text for each TunnelSpec field; the flag is the field name with dashes.
_TUNNEL_HELP: dict[str, str] = {
    "seed": "random seed; the same seed gives a byte-identical file (default 0)",
    "schedule": "fin-command schedule: the paper's Table 1, or a random staircase",
    "steps": "number of staircase steps",
    "fin_range": "staircase levels are uniform in ±this, °",
    "dwell_min": "shortest staircase dwell, s",
    "dwell_max": "longest staircase dwell, s",
    "model": "damping model: theta (eq. 49, default) or constant (eq. 29)",
    "alpha": "steady-state gain α, (°/s)/° (eq. 17: 0.6590)",
    "beta": "steady-state offset β, °/s (eq. 17: 2.8856); θ̄ = β/α",
    "alpha_bar": "ᾱ, 1/(s·°) (eq. 48: -0.0289; 0 for --model constant)",
    "beta_bar": "β̄, 1/s (eq. 48: 2.4075), or the constant a (eq. 46: 1.314)",
    "servo_rate": "servo rate limit, °/s (eq. 23: 60°/0.4 s = 150)",
    "turbulence": "marginal distribution of u_d",
    "turbulence_sd": "standard deviation of u_d, °",
    "turbulence_mean": "mean of u_d, °",
    "correlation_time": "correlation time of u_d, s (0: independent per interval)",
    "dof": "degrees of freedom of the student-t marginal",
    "log_dt": "logging interval, s (the paper: 0.1)",
    "substeps": "exact-update substeps per logging interval",
    "encoder_counts": (
        "encoder counts per revolution (HEDS-5702: 256 cycles read in 4x quadrature = 1024; "
        "0: ideal)"
    ),
    "no_encoder": "omit the encoder angle (needs --gyro-noise)",
    "gyro_noise": "add a rate-gyro column with eq. 52 noise of this many percent",
    "measured_fin": "add the actual (measured) fin angle column fin_deg",
    "name": "recording name (default tunnel-<schedule>-seed<N>)",
}
_CHOICES: dict[str, tuple[str, ...]] = {
    "schedule": ("paper", "staircase"),
    "model": ("theta", "constant"),
    "turbulence": ("gaussian", "laplace", "student-t"),
}


def _add_tunnel_spec_arguments(parser: argparse.ArgumentParser) -> None:
    from identification.tunnel import TunnelSpec

    defaults = TunnelSpec()
    for f in fields(TunnelSpec):
        flag = "--" + f.name.replace("_", "-")
        default = getattr(defaults, f.name)
        help_text = _TUNNEL_HELP[f.name]
        if isinstance(default, bool):
            parser.add_argument(flag, action="store_true", help=help_text)
            continue
        kind: Any = str
        if f.name in ("seed", "steps", "substeps", "encoder_counts"):
            kind = int
        elif f.name not in _CHOICES and f.name != "name":
            kind = float
        parser.add_argument(
            flag, type=kind, default=default, choices=_CHOICES.get(f.name), help=help_text
        )


def _spec_from_namespace(ns: argparse.Namespace) -> TunnelSpec:
    from identification.tunnel import TunnelSpec

    values = {f.name: getattr(ns, f.name) for f in fields(TunnelSpec)}
    try:
        return TunnelSpec(**values)
    except ValueError as exc:
        raise UsageError(f"tunnel: {exc}") from None


def tunnel_spec_from_argv(argv: Sequence[str]) -> TunnelSpec:
    """Parse ``rocketroll tunnel`` arguments (without ``--out``) into a TunnelSpec."""
    parser = argparse.ArgumentParser(prog="rocketroll tunnel", add_help=False)
    _add_tunnel_spec_arguments(parser)
    return _spec_from_namespace(parser.parse_args(list(argv)))


def _cmd_tunnel(ns: argparse.Namespace) -> int:
    from identification.recording import save_recording
    from identification.tunnel import run_tunnel

    spec = _spec_from_namespace(ns)
    recording = run_tunnel(spec)
    save_recording(recording, ns.out)
    print(f"wrote {ns.out}: {recording!r}")
    return 0


def _cmd_info(ns: argparse.Namespace) -> int:
    from identification.recording import load_recording, write_all_atomic
    from identification.summary import plot_recording, summarize

    if ns.plot is not None and ns.plot.suffix.lower() != ".png":
        raise UsageError(f"--plot {ns.plot}: the figure is a PNG; give a path ending in .png")
    recording = load_recording(ns.recording)
    summary = summarize(recording)
    # Everything is computed before anything is written.
    outputs: dict[str | os.PathLike[str], str | bytes] = {}
    if ns.json:
        outputs[ns.json] = json.dumps(summary.to_dict(), indent=2) + "\n"
    if ns.plot:
        outputs[ns.plot] = plot_recording(recording)
    write_all_atomic(outputs)  # all or nothing
    print(summary.format())
    for path in outputs:
        print(f"wrote {path}")
    return 0


def _cmd_import_csv(ns: argparse.Namespace) -> int:
    from identification.importer import import_csv
    from identification.recording import save_recording

    recording = import_csv(
        ns.input,
        ns.columns.split(","),
        header=not ns.no_header,
        units=ns.units,
        rate_hz=ns.rate,
        time_column=ns.time_column,
        time_unit=ns.time_unit,
        delimiter=ns.delimiter,
        unwrap=ns.unwrap,
        name=ns.name,
        source=ns.source,
        notes=ns.notes,
    )
    save_recording(recording, ns.out)
    print(f"wrote {ns.out}: {recording!r}")
    return 0


def register(subparsers: Any) -> None:
    """Add this layer's subcommands to the ``rocketroll`` parser."""
    p = subparsers.add_parser(
        "tunnel",
        help="run the virtual wind tunnel and write a synthetic recording",
        description="Re-create the paper's wind-tunnel experiment with known ground truth "
        "(defaults: the paper's parameters and Table 1 schedule).",
    )
    p.add_argument("--out", required=True, type=Path, help="recording file to write (CSV)")
    _add_tunnel_spec_arguments(p)
    p.set_defaults(handler=_cmd_tunnel)

    p = subparsers.add_parser(
        "info",
        help="validate a recording and print its summary",
        description="Validate a recording (format v1) and print a summary.",
    )
    p.add_argument("recording", type=Path, help="recording file (CSV, format v1)")
    p.add_argument("--json", type=Path, help="also write the summary as JSON here")
    p.add_argument("--plot", type=Path, help="also write a PNG figure (like the paper's Fig. 2)")
    p.set_defaults(handler=_cmd_info)

    p = subparsers.add_parser(
        "import-csv",
        help="convert a foreign CSV/text log into a recording",
        description="Convert a delimited text file (a wind-tunnel or flight log) into a "
        "recording.  Example: rocketroll import-csv run.txt --out run.csv --columns fin,roll "
        "--no-header --units rad --rate 100",
    )
    p.add_argument("input", type=Path, help="input file")
    p.add_argument("--out", required=True, type=Path, help="recording file to write")
    p.add_argument(
        "--columns",
        required=True,
        help="comma-separated role of each input column: time, fin_cmd, fin, roll, roll_rate, skip",
    )
    p.add_argument("--no-header", action="store_true", help="the file has no header row")
    p.add_argument(
        "--units",
        choices=("deg", "rad"),
        default="deg",
        help="unit of angles (and of the rate, per second); default deg",
    )
    time_group = p.add_mutually_exclusive_group()
    time_group.add_argument("--rate", type=float, help="sampling rate in Hz (no time column)")
    time_group.add_argument(
        "--time-column", help="the time column by header name (or 1-based number without header)"
    )
    p.add_argument(
        "--time-unit",
        choices=("s", "ms", "us"),
        default="s",
        help="unit of the time column; default s",
    )
    p.add_argument("--delimiter", help="cell separator (default: , ; or tab, else whitespace)")
    p.add_argument("--unwrap", action="store_true", help="unwrap a roll angle that wraps at 360°")
    p.add_argument("--name", help="recording name (default: the input file's stem)")
    p.add_argument(
        "--source",
        choices=("wind-tunnel", "flight", "synthetic"),
        default="wind-tunnel",
        help="where the data come from (default wind-tunnel)",
    )
    p.add_argument("--notes", help="free-text notes stored in the metadata")
    p.set_defaults(handler=_cmd_import_csv)
