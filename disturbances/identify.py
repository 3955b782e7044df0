"""``rocketroll identify``: a recording identified by every method asked for, printed, and
with ``--report`` judged in figures and ``report.md``, with ``--db`` stored.

The identification is :mod:`identification`'s; storing it (``--db``) is
:mod:`disturbances`' (:mod:`disturbances.cli`'s database helpers), which is why the
command lives here, in the lowest layer that has both.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from disturbances.cli import (
    check_methods,
    check_quadratic,
    methods_help,
    new_database,
    open_store,
)
from identification.methods import default_methods, traits
from identification.methods.pipeline import IdentifyOptions
from identification.recordings.recording import LoopFlags, fin_range_setting
from rocketroll_common.errors import UsageError
from rocketroll_common.settings import Command, check, setting

__all__ = ["COMMANDS", "IdentifyArgs", "identify"]


def _report_files(args: IdentifyArgs) -> list[str]:
    """The files ``--report`` may write, known before the fits: ``report.md``, a figure per
    method asked for (the tunnel's defaults when none is), the paper's figures with its
    method, and a flight's figure."""
    from identification.reports.fitreport import figure_name
    from identification.reports.flightreport import FIGURE_NAME
    from identification.reports.report import FIGURES, REPORT_NAME

    methods = args.method or list(default_methods())
    names = [REPORT_NAME, *(figure_name(m) for m in methods if not traits(m).flight)]
    if "paper" in methods:
        names += list(FIGURES)
    if not args.method or any(traits(m).flight for m in methods):
        names.append(FIGURE_NAME)
    return names


@dataclass(frozen=True)
class IdentifyArgs:
    """``rocketroll identify``."""

    recording: Path = setting(help="recording file (CSV, format v1)", positional=True, input=True)
    json: Path | None = setting(
        None, "also write machine-readable results (JSON) here", output="file", kind="json"
    )
    report: Path | None = setting(
        None,
        "also write PNG figures and report.md into this folder: every method's fit judged "
        "(its model without u_d against the rate, u_d beside the fin), and with the paper's "
        "method the paper's figures",
        output="folder",
        files=_report_files,
    )
    method: list[str] = setting(
        default_factory=list,
        help=methods_help("identification method to run (a flight: flight)"),
        metavar="METHOD",
    )
    db: str | None = setting(
        None,
        "also store the results (every method, both models) in this disturbance database; "
        "created if missing (not for a flight)",
        metavar="DB",
        input=True,
        kind="sqlite",
    )
    together: list[Path] = setting(
        default_factory=list,
        help="another flight of the same rocket, fitted together with RECORDING by the flight "
        "method (one rocket, one turbulence's statistics, one gyro; repeatable)",
        metavar="FLIGHT",
        input=True,
    )
    actuation: bool = setting(
        False,
        "also look for what lies outside the model: a servo lag and backlash (from a measured "
        "fin column), a sensor latency and a damping growing with the roll rate (from the roll "
        "response), each admitted at p < 0.01 (a tunnel run; about 30 s a 100-Hz minute)",
    )
    fin_range_deg: float | None = fin_range_setting(
        "your fins' range, ± this (where the canards stop), over the recording's "
        "rig.fin_range_deg: the fit adequacy measures u_d against it (unstated: the log's "
        "largest |fin|)"
    )
    loop: LoopFlags = setting(default_factory=LoopFlags, flatten=True)
    options: IdentifyOptions = setting(default_factory=IdentifyOptions, flatten=True)

    def __post_init__(self) -> None:
        check(self)
        check_methods(self.method)


def _fit_each(context: Any, methods: Sequence[str]) -> tuple[dict[str, Any], dict[str, str]]:
    """Each method's fits, and the reason of each method that cannot fit the recording (its
    :class:`~identification.methods.steps.IdentificationError`: the paper's method on a recording
    without held fin steps, ...); when none can, the first one's error."""
    from identification.methods import fit
    from identification.methods.steps import IdentificationError

    fits: dict[str, Any] = {}
    refused: dict[str, str] = {}
    first: IdentificationError | None = None
    for method in methods:
        try:
            fits[method] = fit(context, method, traits(method).models)
        except IdentificationError as exc:
            refused[method] = str(exc)
            first = first or exc
    if not fits and first is not None:
        if "needs fin steps" in str(first) and "ml" not in methods:
            raise IdentificationError(f"{first}; --method ml reads no fin steps") from None
        raise first
    return fits, refused


def identify(args: IdentifyArgs) -> int:
    """Identify a recording by every method asked for; print, write and store the results."""
    import dataclasses

    from identification.methods import Context, is_flight_method
    from identification.recordings.recording import load_recording
    from identification.reports.tables import (
        adequacy_table,
        flight_table,
        interval_table,
        methods_table,
        parameter_table,
    )
    from rocketroll_common.files import write_all_atomic

    if args.db is not None and "://" not in args.db:
        from rocketroll_common.files import check_output

        check_output(args.db, "--db", kind="sqlite")  # before the work, as every output
    options = dataclasses.replace(args.options, progress=sys.stderr.isatty())
    recording = load_recording(args.recording).stating_fin_range(args.fin_range_deg)
    recording = recording.stating_loop(args.loop.stated(recording.loop, str(args.recording)))
    fin_range = recording.fin_range()
    together = [load_recording(path) for path in args.together]
    methods = args.method or list(default_methods(recording))
    if args.report is not None and "paper" in methods and recording.is_flight:
        raise UsageError(
            f"--report: the paper's report is of a tunnel run; {args.recording} is a flight"
        )
    if args.actuation and recording.is_flight:
        raise UsageError(f"--actuation: looks at a tunnel run; {args.recording} is a flight")
    check_quadratic(options, methods, recording)
    context = Context(recording, options, together=together)
    fits, refused = _fit_each(context, methods)
    found = None
    if args.actuation:
        from identification.methods.actuation import identify_actuation

        found = identify_actuation(recording, options)
    result = context.paper if "paper" in fits else None
    outputs: dict[str | os.PathLike[str], str | bytes] = {}
    if args.json is not None:
        data = {} if result is None else result.to_dict()
        data["methods"] = {
            method: {
                model: {"params": asdict(f.params), "metrics": dict(f.metrics)}
                for model, f in by_model.items()
            }
            for method, by_model in fits.items()
        }
        if found is not None:
            data["actuation"] = {t.name: asdict(t) for t in found.terms}
        data.update(fin_range.as_dict())  # what |u_d|/range is against, and whence
        outputs[args.json] = json.dumps(_json_safe(data), indent=2, allow_nan=False) + "\n"
    tunnel_fits = {method: f for method, f in fits.items() if not is_flight_method(method)}
    if args.report is not None and tunnel_fits:
        from identification.reports.fitreport import render_fit_report

        paper_report = None
        if result is not None:
            from identification.reports.report import render_report

            paper_report = render_report(result)
        for name, content in render_fit_report(context, tunnel_fits, paper_report).items():
            outputs[args.report / name] = content
    elif args.report is not None and "flight" in fits:
        from identification.reports.flightreport import render_flight_report

        table = flight_table({"flight": fits["flight"]})
        for name, content in render_flight_report(recording, fits["flight"], table).items():
            outputs[args.report / name] = content
    stored = None
    if args.db is not None:  # before any file is written: all or nothing
        from disturbances.ingest import add_identification

        # The fits made above are stored, not made again; a fit with other flights
        # (--together) is not this recording's alone, which is what is stored.
        made = None if together else context
        with new_database(args.db), open_store(args.db, create=True) as db:
            fitted = list(fits)  # a method that refused the recording adds nothing
            if result is not None:
                added = add_identification(db, result, methods=fitted, context=made)
            else:
                from disturbances.ingest import add_recording

                added = add_recording(db, recording, options, methods=fitted, context=made)
        stored = (
            f"{args.db}: this recording is already stored (same samples); nothing added"
            if added.recordings == 0 and added.traces == 0
            else f"stored in {args.db}: {added.identifications} identifications, "
            f"{added.traces} traces (ids {', '.join(map(str, added.trace_ids))})"
        )
    write_all_atomic(outputs, folder=args.report, what="--report")  # all or nothing
    for method, reason in refused.items():  # the others ran
        print(f"rocketroll identify: method {method} cannot fit it: {reason}", file=sys.stderr)
    if result is not None:
        print(parameter_table(result))
    flown = {method: f for method, f in fits.items() if is_flight_method(method)}
    tunnel = tunnel_fits
    if flown:
        print(flight_table(flown))
    if any(method != "paper" for method in tunnel):
        print("\nidentification methods (parameters; re-simulation of each one's u_d, §3.5)")
        print(methods_table(tunnel))
    if tunnel or flown:
        print("\nfit adequacy (the model without u_d against the raw rate, the fin in u_d)")
        print(adequacy_table({**tunnel, **flown}))
        print(f"|u_d|/range: against the fins' {fin_range}{fin_range.hint}")
        intervals = interval_table({**tunnel, **flown})
        if intervals:
            legend_fits = [f for by in tunnel.values() for f in by.values()]
            instrumental = any("instruments" in f.metrics for f in legend_fits)
            loop = any("loop_alone" in f.metrics for f in legend_fits)
            print(
                "\n95 % intervals (hessian: ±1.96 SE; profile: the profile likelihood's, where "
                "the Hessian says nothing, or for all with --intervals profile"
                + ("; fieller, wald: the instrumental fit's" if instrumental else "")
                + ("; loop: what a rate loop alone leaves open" if loop else "")
                + ")"
            )
            print(intervals)
    rig = recording.rig_with(options.rig)
    if not rig.ideal:
        print(f"\nthe rig assumed (stated: the recording's rig.* lines or the flags): "
              f"{rig.describe()}")  # fmt: skip
    if found is not None:
        print()
        print("\n".join(found.lines()))
    if stored:
        print(stored)
    if args.json is not None:
        print(f"wrote {args.json}")
    if args.report is not None:
        figures = sum(str(path).endswith(".png") for path in outputs)
        plural = "" if figures == 1 else "s"
        print(f"wrote {args.report / 'report.md'} and {figures} figure{plural}")
    return 0


def _json_safe(value: Any) -> Any:
    from disturbances.rows import json_safe

    return json_safe(value)


#: The command of this module.
COMMANDS: dict[str, Command] = {
    "identify": Command(
        "identify",
        "identify roll parameters and the disturbance u_d(t) from a recording",
        IdentifyArgs,
        identify,
        "Run the paper's identification (steps 1-6 of Fig. 9, the Monte Carlo noise study and "
        "the disturbance statistics) and the other identification methods on a recording and "
        "print the parameters (beside the ground truth of a synthetic recording).  Defaults "
        "are the paper's.",
    ),
}
