"""``rocketroll`` subcommands of the identification layer.

``tunnel``, ``import-csv``, ``info`` and ``identify``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Sequence
from dataclasses import fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rocketroll_common.errors import UsageError

if TYPE_CHECKING:
    from identification.pipeline import Identification, IdentifyOptions
    from identification.tunnel import TunnelSpec

__all__ = ["add_identify_options", "identify_options", "register", "tunnel_spec_from_argv"]

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
    "split": (
        "evaluation split to record in the metadata (default: none; the disturbance "
        "database then splits by content hash)"
    ),
}
_CHOICES: dict[str, tuple[str, ...]] = {
    "schedule": ("paper", "staircase"),
    "model": ("theta", "constant"),
    "turbulence": ("gaussian", "laplace", "student-t"),
    "split": ("train", "test"),
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
    from identification.recording import load_recording
    from identification.summary import plot_recording, summarize
    from rocketroll_common.files import write_all_atomic

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


# identify: flag -> (IdentifyOptions field, type, help).
_IDENTIFY_FLAGS: dict[str, tuple[str, type, str]] = {
    "--min-step": ("min_step_deg", float, "smallest fin change counted as a step, ° (1)"),
    "--max-breakpoint": ("max_breakpoint_s", float, "ΔT0 of the bi-linear search, s (4)"),
    "--servo-rate": (
        "servo_rate_dps",
        float,
        "servo rate limit for the fin-angle ramp, °/s (eq. 23: 150)",
    ),
    "--outlier-level": (
        "outlier_level",
        float,
        "Bonferroni p below which one step is left out of a(θ) (0.05)",
    ),
    "--smoothing-passes": (
        "smoothing_passes",
        int,
        "3-point moving-average passes on the measured velocity (3)",
    ),
    "--smoothing-window": (
        "smoothing_window_s",
        float,
        "span of one moving-average pass, s (0.3: three points at 10 Hz)",
    ),
    "--ud-interval": ("ud_interval_s", float, "Δt over which u_d is constant, s (0.1)"),
    "--mc-runs": ("noise_runs", int, "Monte Carlo runs per noise level; 0 skips the study (100)"),
    "--mc-seed": ("noise_seed", int, "seed of the noise study (0)"),
}


def _number(kind: type, flag: str) -> Any:
    def parse(text: str) -> Any:
        try:
            return kind(text)
        except ValueError:
            word = "an integer" if kind is int else "a number"
            raise argparse.ArgumentTypeError(f"{flag} must be {word}, not {text!r}") from None

    return parse


def _levels(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--mc-levels must be comma-separated numbers, not {text!r}"
        ) from None


def _pad(text: str, width: int) -> str:
    """Left-justify ``text`` to a display width (combining marks take no column)."""
    import unicodedata

    shown = sum(not unicodedata.combining(ch) for ch in text)
    return text + " " * max(0, width - shown)


def parameter_table(result: Identification) -> str:
    """The text ``rocketroll identify`` prints: parameters, fits, disturbance."""
    import numpy as np

    rec = result.recording
    truth = result.truth()
    paper = {
        "alpha": 0.6590,
        "beta_dps": 2.8856,
        "theta_bar_deg": 4.38,
        "steady_state_r2": 0.9914,
        "a_per_s": 1.314,
        "b_per_s2": 0.8665,
        "alpha_bar_per_deg_s": -0.0289,
        "beta_bar_per_s": 2.4075,
        "damping_vs_fin_r2": 0.8280,
    }
    labels = {
        "alpha": "α (°/s)/°          eq. 16",
        "beta_dps": "β °/s              eq. 16",
        "theta_bar_deg": "θ̄ °               eq. 30",
        "steady_state_r2": "steady-state R²    eq. 16",
        "a_per_s": "a 1/s (constant)   eq. 26",
        "b_per_s2": "b = aα             eq. 30",
        "alpha_bar_per_deg_s": "ᾱ 1/(s·°)          eq. 48",
        "beta_bar_per_s": "β̄ 1/s              eq. 48",
        "damping_vs_fin_r2": "a(θ) R²            eq. 48",
    }
    kind = "synthetic: virtual wind tunnel" if rec.source == "synthetic" else rec.source
    lines = [
        f"{rec.name} ({kind}): {rec.n_samples} samples every {rec.dt_s:g} s, "
        f"{result.segments.n_steps} fin steps",
        f"  angle: {result.angle_source}; velocity: {result.velocity_source}",
        f"  fin angle: {result.theta_source}",
        "",
        f"{'parameter':<26}{'identified':>12}{'truth' if truth else '':>12}{'paper':>10}",
    ]
    for key, value in result.parameters().items():
        true = "" if truth is None or key not in truth else f"{truth[key]:.4g}"
        if truth is not None and key in ("a_per_s", "b_per_s2") and true:
            true += "*"
        lines.append(f"{_pad(labels[key], 26)}{value:>12.4g}{true:>12}{paper[key]:>10.4g}")
    if truth is not None and truth["alpha_bar_per_deg_s"] != 0.0:
        lines.append("  * θ-dependent truth: a(θ) averaged over the step fin levels")
    dvf = result.damping_vs_fin
    if dvf.outlier is not None:
        lines.append(
            f"  a(θ): step {dvf.outlier + 1} left out as an outlier (Bonferroni p = "
            f"{dvf.outlier_p:.3g})"
        )
    if dvf.excluded:
        steps = ", ".join(str(i + 1) for i in dvf.excluded)
        lines.append(f"  a(θ): step(s) {steps} left out, a_i <= 0 is not a damping")
    lines += ["", "step  start s   fin °    v_ss °/s   t0 s    a_i 1/s"]
    for i in range(result.segments.n_steps):
        mark = "  outlier" if dvf.outlier == i else ""
        lines.append(
            f"{i + 1:>4}{result.segments.time_s[i]:>9.1f}{result.segments.step_levels_deg[i]:>8.2f}"
            f"{result.piecewise.slopes_dps[i]:>11.2f}{result.bilinear.t0_s[i]:>7.2f}"
            f"{result.damping.a_steps_per_s[i]:>10.3f}{mark}"
        )
    lines += ["", "re-simulation (§3.5)   rate MAE / SD °/s   angle MAE / SD °"]
    for name, r in result.resimulations.items():
        lines.append(
            f"{name + ' damping':<22}{r.rate_mae_dps:>9.3f} / {r.rate_sd_dps:<9.3f}"
            f"{r.angle_mae_deg:>7.3f} / {r.angle_sd_deg:.3f}"
        )
    st = result.statistics
    lines += ["", "disturbance u_d (§3.4)  90 % interval °     Lilliefors p   normal"]
    for name, trace in (("theta", st.theta), ("constant", st.constant)):
        lines.append(
            f"{'u_d,' + name:<22}[{trace.q05_deg:6.2f}, {trace.q95_deg:6.2f}]"
            f"{trace.lilliefors_p:>15.3g}   {'yes' if trace.normal else 'no'}"
        )
    lines.append(f"two-sample KS between them: p = {st.ks_p:.3g}")
    if rec.ud_true_deg is not None:
        q05, q95 = np.percentile(rec.ud_true_deg, [5, 95])
        lines.append(f"true u_d (synthetic): 90 % interval [{q05:.2f}, {q95:.2f}]")
    if result.noise is not None:
        n = result.noise
        lines += ["", f"noise study (§3.3): {n.runs} runs per level, seed {n.seed}"]
        lines.append("η %     u_d MAE °   P90 °")
        for eta, mae, p90 in zip(n.levels_pct, n.mae_deg, n.p90_deg, strict=True):
            lines.append(f"{eta:<8g}{mae:>9.3f}{p90:>9.3f}")
    return "\n".join(lines)


def add_identify_options(parser: argparse.ArgumentParser) -> None:
    """Add the identification settings (``--min-step`` ... ``--mc-levels``) to a parser."""
    for flag, (name, kind, text) in _IDENTIFY_FLAGS.items():
        parser.add_argument(flag, dest=name, type=_number(kind, flag), help=text)
    parser.add_argument(
        "--mc-levels", type=_levels, help="noise levels η of the study, %% (1,2,5,10)"
    )


def identify_options(ns: argparse.Namespace) -> IdentifyOptions:
    """The :class:`IdentifyOptions` of flags added by :func:`add_identify_options`."""
    from identification.pipeline import IdentifyOptions
    from identification.steps import OptionError

    values: dict[str, Any] = {}
    for name, _, _ in _IDENTIFY_FLAGS.values():
        value = getattr(ns, name)
        if value is not None:
            values[name] = value
    if ns.mc_levels is not None:
        values["noise_levels_pct"] = ns.mc_levels
    values["progress"] = sys.stderr.isatty()
    try:
        options = IdentifyOptions(**values)
    except OptionError as exc:
        flag = next(
            (f for f, (name, _, _) in _IDENTIFY_FLAGS.items() if name == exc.option),
            "--mc-levels",
        )
        raise UsageError(f"{flag} {exc.problem}") from None
    return options


def _cmd_identify(ns: argparse.Namespace) -> int:
    from identification.pipeline import identify
    from identification.recording import load_recording
    from identification.report import render_report
    from rocketroll_common.files import write_all_atomic

    options = identify_options(ns)
    if ns.report is not None and ns.report.exists() and not ns.report.is_dir():
        raise UsageError(f"--report {ns.report}: exists and is not a directory")
    recording = load_recording(ns.recording)
    result = identify(recording, options)
    outputs: dict[str | os.PathLike[str], str | bytes] = {}
    if ns.json is not None:
        outputs[ns.json] = json.dumps(result.to_dict(), indent=2, allow_nan=False) + "\n"
    if ns.report is not None:
        for name, content in render_report(result).items():
            outputs[ns.report / name] = content
        ns.report.mkdir(parents=True, exist_ok=True)
    # A higher layer may keep the result (``rocketroll identify --db``, added by
    # the disturbances layer, which this one does not import).
    store = getattr(ns, "store_result", None)
    stored = store(ns, result) if store is not None else None
    write_all_atomic(outputs)  # all or nothing
    print(parameter_table(result))
    if stored:
        print(stored)
    if ns.json is not None:
        print(f"wrote {ns.json}")
    if ns.report is not None:
        figures = sum(str(path).endswith(".png") for path in outputs)
        print(f"wrote {ns.report / 'report.md'} and {figures} figures")
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

    p = subparsers.add_parser(
        "identify",
        help="identify roll parameters and the disturbance u_d(t) from a recording",
        description="Run the paper's identification (steps 1-6 of Fig. 9, the Monte Carlo "
        "noise study and the disturbance statistics) on a recording and print the parameters "
        "(beside the ground truth of a synthetic recording).  Defaults are the paper's.",
    )
    p.add_argument("recording", type=Path, help="recording file (CSV, format v1)")
    p.add_argument("--json", type=Path, help="also write machine-readable results (JSON) here")
    p.add_argument(
        "--report", type=Path, help="also write PNG figures and report.md into this directory"
    )
    add_identify_options(p)
    p.set_defaults(handler=_cmd_identify)
