"""``LearnedController``: a policy trained by :mod:`agents.train` (PPO, SAC or TD3), as a
:class:`Controller`; with the observation history it was trained with (:mod:`agents.memory`)."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents.actor import ActorChain
from agents.base import Design, FlightView
from agents.memory import PolicyLayout, PolicyObservation, observation_names
from agents.observer import ObserverFeatures
from agents.registry import COMMITTED, shipped_path
from disturbances.bank import TraceBank
from rollenv.config import RollConfig
from rollenv.layout import Obs

__all__ = [
    "COMMITTED",
    "LearnedController",
    "ObservationNormalizer",
    "check_run",
    "make_learned",
    "make_ppo",
]


class ObservationNormalizer:
    """The observation normalisation of training, from ``normalize.json``.

    Computes what SB3's ``VecNormalize`` does (``norm_obs``)::

        clip((obs - mean) / sqrt(var + epsilon), -clip_obs, clip_obs)

    in float64, cast to float32 -- the same operations in the same order, so
    the policy sees bit for bit what it saw in training.

    Parameters
    ----------
    record : dict
        The contents of ``normalize.json``: ``norm_obs`` and, when True,
        ``mean``, ``var``, ``clip_obs``, ``epsilon``.
    size : int
        Values per observation (``len(Obs)``, more with a history).
    """

    def __init__(self, record: dict[str, Any], size: int = len(Obs)) -> None:
        self.enabled = bool(record.get("norm_obs", False))
        if self.enabled:
            try:
                self.mean = np.asarray(record["mean"], dtype=np.float64)
                self.var = np.asarray(record["var"], dtype=np.float64)
                self.clip_obs = float(record["clip_obs"])
                self.epsilon = float(record["epsilon"])
            except KeyError as exc:
                raise ValueError(f"normalize.json lacks {exc.args[0]!r}") from exc
            n = size
            if self.mean.shape != (n,) or self.var.shape != (n,):
                raise ValueError(
                    f"normalize.json: mean and var must hold {n} values, got {self.mean.shape} "
                    f"and {self.var.shape}"
                )
            self._scale = np.sqrt(self.var + self.epsilon)

    def __call__(self, obs: NDArray[Any]) -> NDArray[np.float32]:
        """``obs`` (shape ``(..., size)``) normalised as in training, float32."""
        if not self.enabled:
            return np.asarray(obs, dtype=np.float32)
        normalized = np.clip((obs - self.mean) / self._scale, -self.clip_obs, self.clip_obs)
        return normalized.astype(np.float32)


class LearnedController:
    """A trained PPO policy (deterministic: the Gaussian's mean) for the evaluation protocol.

    Load it with :meth:`load` from a training output directory
    (``model.zip``, ``normalize.json``, ``settings.json``).  :meth:`act`
    normalises the observation as training did and evaluates the actor's
    layers with :class:`agents.actor.ActorChain`: the same bits on every
    processor, within float32 rounding of ``model.predict(obs,
    deterministic=True)`` (which differs between processors), and faster.

    Attributes
    ----------
    name : str
        ``"PPO"``.
    model : stable_baselines3.PPO
        The loaded model.
    normalizer : ObservationNormalizer
        The observation normalisation of training.
    settings : dict
        ``settings.json`` of the run (empty if the file is absent).
    task : str or None
        ``"angle"`` or ``"rate"``, from the settings; :meth:`reset` refuses
        an environment of the other task.
    """

    name = "PPO"

    def __init__(
        self, model: Any, normalizer: ObservationNormalizer, settings: dict[str, Any]
    ) -> None:
        self.model = model
        self.normalizer = normalizer
        self.settings = settings
        self.algorithm: str = settings.get("algorithm", "ppo")
        self.name = self.algorithm.upper()
        env_settings = settings.get("env_settings") or {}
        self.task: str | None = env_settings.get("task")
        #: What the policy reads and sends beyond the observation and the command.
        self.layout = layout = PolicyLayout.from_settings(settings)
        #: The policy reads the observer's estimate: :meth:`attach_observer` before acting.
        self.needs_observer = layout.observer
        #: The policy reads the flight's phase: it flies a flight variant.
        self.needs_clock = layout.flight_clock
        self.features: ObserverFeatures | None = None
        #: What the policy sees and sends (:class:`agents.memory.PolicyObservation`, as in
        #: training), made at :meth:`reset` from the environment (None before).
        self.observation: PolicyObservation | None = None
        self._dim = int(np.prod(model.observation_space.shape))
        model.policy.set_training_mode(False)
        #: The actor's layers, evaluated alike on every processor (None: torch acts); a copy
        #: of the weights: remake it (ActorChain.from_policy) after changing them.
        self.chain = ActorChain.from_policy(model.policy)

    @classmethod
    def load(
        cls, path: str | os.PathLike[str], checkpoint: str | os.PathLike[str] | None = None
    ) -> LearnedController:
        """The controller of the training output directory ``path``; with ``checkpoint``
        (one of the run's ``checkpoints/<algo>_<N>_steps.zip``), that checkpoint's model
        and observation normalisation instead of the final ones (a learning curve:
        ``benchmarks/run_curve.py``).

        Raises
        ------
        FileNotFoundError
            ``model.zip`` or ``normalize.json`` (the checkpoint or its ``VecNormalize``
            statistics) is missing.
        """
        from agents.train import algorithm_class

        folder = Path(path)
        settings_file = folder / "settings.json"
        settings: dict[str, Any] = (
            json.loads(settings_file.read_text(encoding="utf-8")) if settings_file.is_file() else {}
        )
        algorithm = str(settings.get("algorithm", "ppo"))
        layout = PolicyLayout.from_settings(settings)
        if checkpoint is None:
            model_file = folder / "model.zip"
            norm_file = folder / "normalize.json"
            for required in (model_file, norm_file):
                if not required.is_file():
                    raise FileNotFoundError(f"{required}: not found (a `rocketroll train` output?)")
            record = json.loads(norm_file.read_text(encoding="utf-8"))
        else:
            from agents.train.checkpoints import checkpoint_normalization

            model_file = Path(checkpoint)
            if not model_file.is_file():
                raise FileNotFoundError(f"{model_file}: not found")
            trained = (settings.get("hyperparameters") or {}).get("normalize")
            record = checkpoint_normalization(
                model_file,
                algorithm,
                layout,
                required=isinstance(trained, dict) and bool(trained.get("norm_obs", True)),
            )
        size = len(observation_names(layout))
        normalizer = ObservationNormalizer(record, size)
        # Schedules are pickled closures; acting needs none of them.
        custom = {"learning_rate": 0.0, "lr_schedule": _zero, "clip_range": _zero}
        model = algorithm_class(algorithm).load(model_file, device="cpu", custom_objects=custom)
        return cls(model, normalizer, settings)

    def require_task(self, task: str) -> None:
        """Refuse (``ValueError``) to act for a task the policy was not trained on."""
        if self.task is not None and task != self.task:
            raise ValueError(
                f"this {self.name} policy was trained on the {self.task!r} task, the env is "
                f"{task!r}"
            )

    def attach_observer(self, config: RollConfig, train_bank: TraceBank) -> None:
        """Build the observer whose estimate the policy reads, on the *train* split (as
        training did); ``--policy`` does this."""
        self.features = ObserverFeatures.from_bank(config, train_bank, 1, self.layout.residual)

    def reset(self, env: FlightView) -> None:
        """A new episode: what the policy sees starts afresh (its history, the observer's
        state, the flight's clock, the error's integral); checks the task."""
        config = env.config
        self.require_task(config.task)
        scales = None
        if self.needs_clock:
            if config.flight_schedule is None:
                raise ValueError(
                    f"this {self.name} policy reads the flight's phase: it flies a flight "
                    "variant (RocketRollFlight-v0, ...), not the tunnel"
                )
            scales = config.flight_schedule.scales[: config.max_episode_steps]
        if self.needs_observer and self.features is None:
            raise RuntimeError(
                "this policy reads the observer's estimate: call attach_observer(config, "
                "train_bank) first (--policy does)"
            )
        self.observation = PolicyObservation(
            self.layout,
            1,
            dt_s=config.dt_s,
            fin_range_deg=config.fin_range_deg,
            features=self.features,
            scales=scales,
        )
        self.observation.clear()

    def act(self, obs: NDArray[np.float32], env: FlightView) -> NDArray[np.float32]:
        """The fin command, float32 of shape (1,) in [-1, 1], of the deterministic action
        for ``obs``."""
        if self.observation is None:
            raise RuntimeError("reset(env) first: what the policy sees starts with it")
        seen = self.observation.observe(np.asarray(obs, dtype=np.float32).reshape(1, len(Obs)))
        return self.observation.command(self._action(seen)).reshape(1)

    def _action(self, seen: NDArray[np.float32]) -> NDArray[np.float32]:
        """The deterministic action for the policy's observation ``seen`` (with history)."""
        if self.chain is None:
            return self._predict(seen)
        return self.chain(self.normalizer(seen)).reshape(1)

    def predict(self, obs: NDArray[np.float32]) -> NDArray[np.float32]:
        """The same action through SB3's ``model.predict`` (the reference :meth:`act` matches)
        on ``obs``, the whole vector the policy reads (for a policy with a history, observer
        estimate, flight phase or error integral, those too: :meth:`act` builds it); the
        policy's action, which for an incremental or residual policy is not yet the command
        :meth:`act` returns."""
        return self._predict(np.asarray(obs, dtype=np.float32).reshape(1, self._dim))

    def _predict(self, seen: NDArray[np.float32]) -> NDArray[np.float32]:
        action, _ = self.model.predict(self.normalizer(seen), deterministic=True)
        return np.asarray(action, dtype=np.float32).reshape(1)


def _zero(_: float) -> float:
    return 0.0


def make_ppo(design: Design) -> LearnedController:
    """``--policy ppo[:DIR]``: a training output, or the committed policy of the env id."""
    return make_learned(design, "ppo")


def _run_folder(algorithm: str, arg: str | None, env_id: str) -> Path:
    """The training output ``--policy ALGO[:DIR]`` names (PPO: by default the committed
    policy of the env id)."""
    if arg:
        return shipped_path(arg)
    if algorithm == "ppo":
        return COMMITTED / env_id
    raise ValueError(f"--policy {algorithm}:DIR needs the folder of a training run")


def check_run(algorithm: str, arg: str | None, env_id: str) -> None:
    """Refuse (``ValueError``, naming the value) a ``--policy ALGO[:DIR]`` whose folder is not
    a ``rocketroll train ALGO`` output: no folder, no ``model.zip`` or ``normalize.json``,
    or another algorithm's run.  The registry's check, before any design."""
    path = _run_folder(algorithm, arg, env_id)
    shown = f"--policy {algorithm}{f':{arg}' if arg else ''}"
    if not path.is_dir():
        raise ValueError(f"{shown}: no such folder {path} (a `rocketroll train` output?)")
    for required in ("model.zip", "normalize.json"):
        if not (path / required).is_file():
            raise ValueError(
                f"{shown}: {path / required}: not found (a `rocketroll train` output?)"
            )
    settings_file = path / "settings.json"
    if settings_file.is_file():
        try:
            trained = str(
                json.loads(settings_file.read_text(encoding="utf-8")).get("algorithm", "ppo")
            )
        except (ValueError, AttributeError):
            raise ValueError(f"{shown}: {settings_file}: not a run's settings (JSON)") from None
        if trained != algorithm:
            raise ValueError(
                f"{shown}: that run trained {trained.upper()}, not {algorithm.upper()} (use "
                f"--policy {trained}:{arg or path})"
            )


def make_learned(design: Design, algorithm: str) -> LearnedController:
    """``--policy ALGO[:DIR]``: a ``rocketroll train ALGO`` output (PPO: by default the
    committed policy of the env id)."""
    path = _run_folder(algorithm, design.arg, design.env_id)
    try:
        learned = LearnedController.load(path)
    except FileNotFoundError as exc:
        raise ValueError(str(exc)) from None
    if learned.algorithm != algorithm:
        raise ValueError(
            f"--policy {algorithm}:{path}: that run trained {learned.algorithm.upper()}, not "
            f"{algorithm.upper()} (use --policy {learned.algorithm}:{path})"
        )
    try:
        learned.require_task(design.config.task)
    except ValueError as exc:
        raise ValueError(f"--policy {algorithm}:{path}: {exc} ({design.env_id})") from None
    if learned.needs_observer:
        _check_observer_design(learned, design.config, f"--policy {algorithm}:{path}")
        learned.attach_observer(design.config, design.design_bank)
    if design.arg:
        learned.name = f"{learned.name} {path.name}"
    elsewhere = trained_elsewhere(learned.settings, design)
    if elsewhere:
        learned.name = f"{learned.name} ({elsewhere})"
    return learned


def trained_elsewhere(settings: Mapping[str, Any], design: Design) -> str | None:
    """How a learned policy's training differs from the rockets it is evaluated on, for
    its label (``None``: the same selection): another database, or the whole split where
    one recording is evaluated (a policy trained on the bundled rockets, evaluated on a
    user's)."""
    trained = settings.get("env_settings") or {}
    trained_db = (settings.get("args") or {}).get("db")
    here, there = design.db, trained_db
    if (here is None) != (there is None) or (
        here is not None and there is not None and Path(here).resolve() != Path(there).resolve()
    ):
        return "trained on another database's rockets"
    recording = design.config.recording
    if recording is not None and trained.get("recording") != recording:
        return f"trained on other rockets than {recording}"
    return None


def _check_observer_design(learned: LearnedController, config: RollConfig, where: str) -> None:
    """Refuse (``ValueError``) to design a policy's observer on another method's or model's
    rockets and traces than training designed it on (another ``--set method=`` given to
    ``train`` than to this command): the policy reads that observer's estimate.  The
    disturbance and recording replayed may differ (a design reads the train split:
    :func:`agents.base.train_bank`)."""
    trained = learned.settings.get("env_settings") or {}
    for name in ("method", "model"):
        if name in trained and trained[name] != getattr(config, name):
            raise ValueError(
                f"{where}: its policy reads an observer designed with {name}={trained[name]!r} "
                f"(training's environment), this environment has {name}="
                f"{getattr(config, name)!r}; give the same --set {name}=... as training did"
            )


def make_sac(design: Design) -> LearnedController:
    """``--policy sac:DIR``."""
    return make_learned(design, "sac")


def make_td3(design: Design) -> LearnedController:
    """``--policy td3:DIR``."""
    return make_learned(design, "td3")
