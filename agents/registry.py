"""Controllers by name: one registry behind ``--policy NAME[:ARG]``.

A controller joins the evaluation protocol by one call::

    from agents.registry import register_controller

    def make_mine(design):                  # design: what the controller may know
        return MyController(design.config, NominalModel.from_bank(design.train_bank))

    register_controller("mine", make_mine, usage="mine", summary="my controller")

after which ``rocketroll eval --policy mine`` (and ``--policy mine:ARG``, the
text after the colon in ``design.arg``) runs it, its ``--help`` lists it,
and the evaluation's tables and plots include it.  The factory gets a
:class:`~agents.base.Design`: the environment's settings and id, and -- for
controllers designed on data -- the *train* split of the database, never the
test split the protocol evaluates on.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path

from agents.base import Controller, Design
from rocketroll_common.registry import Registry
from rollenv.config import RollConfig

__all__ = [
    "COMMITTED",
    "CONTROLLERS",
    "available",
    "check_policy",
    "default_policies",
    "flies",
    "has_committed",
    "make_controller",
    "no_argument",
    "policy_help",
    "register_controller",
    "shipped_path",
    "unnamed_defaults",
]


#: ``factory(design) -> controller``.
Factory = Callable[[Design], Controller]
#: ``check(name, arg, env_id)``: refuse (``ValueError``) a ``--policy NAME:ARG`` whose
#: argument the factory would refuse, without designing anything (no database opened).
ArgumentCheck = Callable[[str, "str | None", str], None]

#: Where the committed policies are: one folder per environment id.
COMMITTED = Path(__file__).resolve().parent / "policies"


def shipped_path(given: str) -> Path:
    """``given`` as a path; a relative one that is not there but names a folder shipped with
    the package (``agents/policies/seeds/...``, as the docs write it from the repository)
    is the installed package's."""
    path = Path(given)
    if not path.exists() and not path.is_absolute():
        installed = COMMITTED.parents[1] / path
        if installed.exists():
            return installed
    return path


def has_committed(env_id: str) -> bool:
    """Whether a PPO policy is committed for ``env_id`` (``agents/policies/ENV_ID``)."""
    return (COMMITTED / env_id / "model.zip").is_file()


def flies(env_id: str) -> bool:
    """Whether ``env_id`` is a flight variant (its options set ``flight``)."""
    from rollenv.variants import variant_options

    return variant_options(env_id).get("flight") is not None


#: Every controller, by the name ``--policy`` takes.
CONTROLLERS: Registry[Factory] = Registry("controller")


def register_controller(
    name: str,
    factory: Factory | str,
    *,
    usage: str | None = None,
    summary: str = "",
    default: bool = False,
    replace: bool = False,
    available: Callable[[str], bool] | None = None,
    check: ArgumentCheck | str | None = None,
) -> None:
    """Register a controller for ``--policy NAME`` (``factory`` or ``"module:function"``).

    ``usage`` shows its argument in ``--help`` (``pid[:OMEGA]``); ``default``
    puts it among the controllers ``rocketroll eval`` runs without
    ``--policy``; ``available(env_id)`` says whether it can run on an
    environment without an argument (the committed PPO policy exists for some
    ids only), else the default set leaves it out there.  ``check(name, arg, env_id)``
    (or ``"module:function"``) refuses a bad ``ARG`` with a ``ValueError`` before any work
    (:func:`check_policy`: the commands call it before they open the database); without
    one the argument is the factory's to refuse.
    """
    CONTROLLERS.register(
        name,
        factory,
        summary=summary,
        replace=replace,
        usage=usage or name,
        default=default,
        available=available,
        check=check,
    )


def no_argument(name: str, arg: str | None, env_id: str) -> None:
    """The ``check`` of a controller that takes no argument."""
    if arg:
        raise ValueError(f"--policy {name} takes no argument, got {name}:{arg}")


def check_policy(text: str, env_id: str) -> None:
    """Refuse (``ValueError``, naming the value) a ``--policy NAME[:ARG]`` that names no
    controller or whose argument its registered ``check`` refuses; reads no database."""
    name, _, arg = text.partition(":")
    try:
        entry = CONTROLLERS.entry(name)
    except ValueError as exc:
        raise ValueError(f"--policy {text}: {exc}") from None
    check = entry.info.get("check")
    if isinstance(check, str):
        module, _, function = check.partition(":")
        check = getattr(importlib.import_module(module), function)
    if check is not None:
        check(name, arg or None, env_id)


def default_policies() -> list[str]:
    """The controllers ``rocketroll eval`` runs when none is named, in table order (on a
    given environment: those of them :func:`available` there, :func:`unnamed_defaults`)."""
    return [e.name for e in CONTROLLERS.entries() if e.info.get("default")]


def available(name: str, env_id: str) -> bool:
    """Whether controller ``name`` runs on ``env_id`` without an argument."""
    check = CONTROLLERS.entry(name).info.get("available")
    return check is None or bool(check(env_id))


def unnamed_defaults(chosen: list[str], defaults: list[str], env_id: str) -> list[str]:
    """``chosen``, unless it is a command's ``defaults`` (no ``--policy`` named): then those
    of them available on ``env_id`` (the commands print what they run)."""
    if chosen != defaults:
        return chosen
    return [p for p in defaults if available(p, env_id)]


def policy_help() -> str:
    """``trim | pid[:OMEGA] | ...`` with a word on each, for ``--help``."""
    return "; ".join(
        f"{e.info['usage']}: {e.summary}" if e.summary else str(e.info["usage"])
        for e in CONTROLLERS.entries()
    )


def make_controller(
    text: str, config: RollConfig, env_id: str, *, db: str | None = None
) -> Controller:
    """The controller a ``--policy NAME[:ARG]`` value names (``ValueError`` if unknown)."""
    name, _, arg = text.partition(":")
    try:
        factory = CONTROLLERS.get(name)
    except ValueError as exc:
        raise ValueError(f"--policy {text}: {exc}") from None
    return factory(Design(config, env_id, arg or None, db))


register_controller(
    "trim",
    "agents.nominal:make_trim",
    check=no_argument,
    summary="fins held at the nominal trim -θ̄ (the floor)",
    default=True,
)
register_controller(
    "pid",
    "agents.pid:make_pid",
    check="agents.pid:check_omega",
    usage="pid[:OMEGA]",
    summary="PID placed on the nominal rocket (OMEGA: bandwidth, rad/s)",
    default=True,
)
register_controller(
    "pid-tunnel",
    "agents.pid:make_tunnel_pid",
    check="agents.pid:check_omega",
    usage="pid-tunnel[:OMEGA]",
    summary="the PID with the tunnel's fixed gains, unscheduled in flight (the cautionary row)",
    default=True,
    available=flies,
)
register_controller(
    "observer",
    "agents.observer:make_observer",
    check=no_argument,
    summary="u_d estimated on the fly (Kalman filter) and cancelled, LQR on the estimate",
    default=True,
)
register_controller(
    "mpc",
    "agents.mpc:make_mpc",
    check="agents.mpc:check_horizon",
    usage="mpc[:HORIZON]",
    summary="the observer's estimate, a plan over HORIZON steps (1 to 100, default 20) within the "
    "servo's rate and range limits, solved by OSQP each step",
    default=True,
)
register_controller(
    "ppo",
    "agents.learned:make_ppo",
    check="agents.learned:check_run",
    usage="ppo[:DIR]",
    summary="a trained PPO policy (DIR: a `rocketroll train ppo` output; default: the "
    "committed policy agents/policies/ENV_ID)",
    default=True,
    available=has_committed,
)
register_controller(
    "sac",
    "agents.learned:make_sac",
    check="agents.learned:check_run",
    usage="sac:DIR",
    summary="a trained SAC policy (DIR: a `rocketroll train sac` output)",
)
register_controller(
    "td3",
    "agents.learned:make_td3",
    check="agents.learned:check_run",
    usage="td3:DIR",
    summary="a trained TD3 policy (DIR: a `rocketroll train td3` output)",
)
register_controller(
    "oracle",
    "agents.oracle:make_oracle",
    check=no_argument,
    summary="perfect preview of u_d on the true rocket (a bound, not deployable)",
    default=True,
)
register_controller(
    "causal-oracle",
    "agents.oracle:make_causal_oracle",
    check=no_argument,
    summary="the true rocket and state and the u_d now, its future drawn from the design "
    "split's turbulence model (the causal limit, not deployable)",
    default=True,
)
