"""How the commands that run episodes on a database choose what they replay.

``rocketroll eval``, ``tune``, ``train``, ``seeds``, ``robustness`` and ``sweep
run`` take the same ``--set KEY=VALUE`` environment options and read them
the same way, through :func:`options_config`: the replay (``method``: whose
rockets and ``u_d`` traces; ``disturbance``: identified traces, posterior
draws, surrogates or none; ``model``; ``recording``: one recording of the
split by name) and any other option of :class:`rollenv.config.RollConfig`.
A database that lacks the selection says so in one line, with what it holds
and the command that adds the rest (:class:`disturbances.bank.BankError`).

This module imports nothing heavy: the commands' argument classes use it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from rocketroll_common.errors import UsageError
from rocketroll_common.settings import setting

if TYPE_CHECKING:
    from disturbances.bank import TraceBank
    from rollenv.config import RollConfig

__all__ = [
    "FIXED_OPTIONS",
    "check_options",
    "db_setting",
    "env_options_setting",
    "fit_episode",
    "fitted_settings",
    "options_config",
    "recording_setting",
    "replay_config",
    "replay_options",
    "split_setting",
    "unreliable_note",
]

#: Environment options a command sets itself (``--env-id``, ``--split``), never ``--set``.
FIXED_OPTIONS = ("task", "split")


def db_setting() -> Any:
    """The ``--db`` setting of the commands that replay a database's traces."""
    return setting(
        None,
        "database (default: $ROCKETROLL_DB or the default database)",
        metavar="DB",
        input=True,
        kind="sqlite",
    )


def split_setting() -> Any:
    """The ``--split`` setting of the commands that run the protocol's episodes."""
    return setting(
        "test", "database split the episodes come from (the held-out test split)", always=True
    )


def env_options_setting() -> Any:
    """The ``--set KEY=VALUE`` setting of the commands that run episodes on a database
    (eval, tune, train, seeds, robustness, sweep run): environment options, among them
    the replay (``method``, ``disturbance``, ``model``, ``recording``); read by
    :func:`options_config`."""
    return setting(
        default_factory=dict,
        help="an environment option for every episode, e.g. setpoint=zero, or the replay: "
        "method=paper, disturbance=replay, recording=NAME (repeatable)",
        flag="--set",
        metavar="KEY=VALUE",
    )


def recording_setting() -> Any:
    """The ``--recording NAME`` setting of the commands that run episodes on a database:
    one recording of the split (``--set recording=NAME``), and designs on its part in
    the train split where it has one (``rocketroll db add --holdout``)."""
    return setting(
        None,
        "replay one recording of the database by name (as `rocketroll db list` shows it); "
        "model-based designs then read its part in the train split where it has one "
        "(`db add --holdout`), and an episode fits its trace",
        metavar="NAME",
    )


def replay_options(settings: Mapping[str, Any], recording: str | None) -> dict[str, Any]:
    """The ``--set`` options with ``--recording`` among them (``UsageError`` where both
    name a recording and differ)."""
    given = settings.get("recording")
    if recording is None:
        return dict(settings)
    if given is not None and given != recording:
        raise UsageError(f"--recording {recording} and --set recording={given} differ")
    return {**settings, "recording": recording}


def fit_episode(
    config: RollConfig, banks: Sequence[TraceBank], settings: Mapping[str, Any]
) -> tuple[RollConfig, str | None]:
    """``config`` with an episode as long as the shortest of ``banks``' longest traces
    (whole control steps) where one recording is replayed, that is shorter than the
    default episode and ``--set episode_s`` was not given; and the line that says so
    (None: unchanged)."""
    if config.recording is None or "episode_s" in settings or config.flight is not None:
        return config, None
    longest = min(bank.longest_s for bank in banks)
    steps = math.floor(longest / config.dt_s + 1e-9)
    if steps * config.dt_s >= config.episode_length_s or steps < 2:
        return config, None
    fitted = replace(config, episode_s=round(steps * config.dt_s, 9))
    return fitted, (
        f"  episode: {fitted.episode_length_s:g} s, the length of {config.recording}'s "
        f"trace (--set episode_s=... for another)"
    )


def fitted_settings(
    env_id: str, settings: Mapping[str, Any], recording: str | None, db: str | None
) -> tuple[dict[str, Any], str | None]:
    """The ``--set`` options with ``--recording``, and ``episode_s`` fitted to the
    shortest of the traces a command that trains on one split and checks on the other
    replays (train, sweep run): the recording's in the train split, the whole test split
    (training's held-out check) and the recording's there (an evaluation of it); with
    the line that says so (None: not fitted)."""
    from rollenv.bank import find_bank, load_bank

    options = replay_options(settings, recording)
    if options.get("recording") is None or "episode_s" in options:
        return options, None
    config = options_config(env_id, options, "train")
    banks = [load_bank(config, db), load_bank(replace(config, split="test", recording=None), db)]
    held = find_bank(replace(config, split="test"), db)  # None: the whole test split checked
    if held is not None:
        banks.append(held)
    config, note = fit_episode(config, banks, options)
    if note is None:
        return options, None
    return {**options, "episode_s": config.episode_s}, note


def replay_config(
    env_id: str,
    settings: Mapping[str, Any],
    recording: str | None,
    split: str,
    db: str | None,
) -> tuple[RollConfig, TraceBank, dict[str, Any], str | None]:
    """What a command replays: the configuration (:func:`options_config` of the ``--set``
    options with ``--recording``, its episode fitted to the recording's trace by
    :func:`fit_episode`, or for a stored flight flown as that rocket to the whole flight),
    the bank of ``split``, the options (with the fitted ``episode_s``: what a rerun or a
    Minari dataset needs), and the line that says the episode was fitted (None: it was
    not).  An ``episode_s`` longer than the stored flight is a ``UsageError`` that says
    what to set, before any work."""
    from rollenv.bank import load_bank, stored_flight_config

    options = replay_options(settings, recording)
    given = options.get("episode_s")
    # The episode is checked against the ascent flown: a stored flight's, not the variant's.
    config = options_config(
        env_id, {name: v for name, v in options.items() if name != "episode_s"}, split
    )
    try:  # a stored flight, flown as that rocket
        flown = stored_flight_config(config, db, given)
    except (TypeError, ValueError) as exc:
        raise UsageError(f"--set: {exc}") from None
    note = None
    if flown.flies_stored_flight and not config.flies_stored_flight:
        options = {
            **options,
            "flight": flown.flight,
            "method": flown.method,
            "flight_turbulence": flown.flight_turbulence,
        }
        schedule = flown.flight_schedule
        if given is None and schedule is not None:
            options["episode_s"] = flown.episode_s
            note = (
                f"  episode: {flown.episode_length_s:g} s, {flown.recording}'s stored flight "
                f"from {3.6 * schedule.v_ref_mps:.0f} km/h on (--set episode_s=... for less)"
            )
    config = flown
    bank = load_bank(config, db)
    config, fitted = fit_episode(config, [bank], options)
    note = fitted or note
    if fitted is not None:
        options = {**options, "episode_s": config.episode_s}
    return config, bank, options, note


def unreliable_note(banks: Sequence[TraceBank], db: str | None) -> str | None:
    """The line an evaluation's table carries where one of ``banks`` (of database ``db``)
    replays a recording stored although every fit of it is judged unreliable (``rocketroll
    db add --accept-unreliable``:
    :attr:`disturbances.rows.IdentificationRow.accepted_unreliable`); None where none
    does."""
    judged = {t.recording for bank in banks for t in bank.traces if t.verdict == "unreliable"}
    if not judged:
        return None
    from pathlib import Path

    from disturbances.default import open_database

    database = open_database(None if db is None else Path(db))
    try:
        accepted = {
            row.recording
            for row in database.identifications(verdict="unreliable")
            if row.accepted_unreliable
        }
    finally:
        database.close()
    names = sorted(judged & accepted)
    if not names:
        return None
    whose = "whose fits were" if len(names) == 1 else "recordings whose fits were all"
    return (
        f"note: replays {', '.join(names)}, {whose} judged unreliable (stored with "
        "--accept-unreliable)"
    )


def check_options(options: Mapping[str, Any], flag: str = "--set") -> None:
    """Refuse (``UsageError``) an option the command sets itself (:data:`FIXED_OPTIONS`)."""
    fixed = [name for name in FIXED_OPTIONS if name in options]
    if fixed:
        raise UsageError(
            f"{flag} {fixed[0]}=... is not allowed: the command sets the task (from the "
            "environment id) and the split itself"
        )


def options_config(
    env_id: str, options: Mapping[str, Any], split: str, flag: str = "--set"
) -> RollConfig:
    """The configuration the commands that run episodes on a database replay: the variant
    ``env_id`` with the ``--set`` options (the replay: which method's rockets and ``u_d``,
    which disturbance, model and recording) on ``split``.  One reading for every command,
    so ``--set method=paper`` selects the same traces in each; a bad option is a
    ``UsageError`` that names ``flag``."""
    from rollenv.bank import variant_config

    check_options(options, flag)
    try:
        return variant_config(env_id, {**options, "split": split})
    except (TypeError, ValueError) as exc:
        raise UsageError(f"{flag}: {exc}") from None
