"""A trained policy's deterministic action, computed with the same bits on every processor.

torch computes a layer with the kernels of the processor it runs on (MKL's
and its own, chosen at load time: AVX-512, AVX2 or SSE), and their sums round
differently, so the same policy gives actions that differ in the last bit
between machines -- enough to move an evaluation's figures (one float32 unit
on every action moves the angle table's PPO row in its third digit).
:class:`ActorChain` evaluates the actor's layers -- linear maps and ``tanh`` /
``ReLU`` between them, the chain SB3's MLP policies are made of -- in float64,
summing each row in order in a compiled loop that no processor reorders
(numba, no fast-math), and rounds the action to float32 at the end.  It
differs from torch's float32 forward pass by float32 rounding (about 1e-7).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from rocketroll_common.arrays import FloatArray

__all__ = ["ActorChain"]

#: Activation codes of the compiled forward pass.
_IDENTITY, _TANH, _RELU = 0, 1, 2


@numba.njit(cache=True, nogil=True)
def _forward(x: FloatArray, weights: FloatArray, table: NDArray[np.int64]) -> FloatArray:
    """The chain's output for input ``x``; ``table`` rows are ``(rows, cols, weight
    offset, bias offset, activation)`` of each layer in ``weights`` (row-major)."""
    current = x.copy()
    for k in range(table.shape[0]):
        rows, cols, w0, b0, activation = table[k]
        out = np.empty(rows)
        for i in range(rows):
            acc = 0.0
            row = w0 + i * cols
            for j in range(cols):
                acc += weights[row + j] * current[j]
            value = acc + weights[b0 + i]
            if activation == _TANH:
                value = math.tanh(value)
            elif activation == _RELU:
                value = max(value, 0.0)
            out[i] = value
        current = out
    return current


def _flat_box(space: Any) -> bool:
    """Whether SB3 passes observations of ``space`` to the network as they are: a 1-D
    ``Box`` (not one-hot encoded as discrete spaces are, nor scaled as images are)."""
    from gymnasium import spaces

    return isinstance(space, spaces.Box) and len(space.shape) == 1


@dataclass(frozen=True)
class ActorChain:
    """The deterministic action of an SB3 MLP policy (PPO, A2C, SAC, TD3) as a chain of
    layers, evaluated with :func:`_forward`.

    Attributes
    ----------
    weights : ndarray
        Every layer's weights (row-major) and biases, float64.
    table : ndarray of int64, shape (layers, 5)
        Per layer: rows, columns, weight offset, bias offset, activation code.
    squashed : bool
        The policy's action is ``tanh`` of the chain, mapped onto the action
        space (SAC, TD3: ``policy.unscale_action``); otherwise the chain clipped to
        it (PPO, A2C).
    low, high : ndarray
        The action space's bounds, float64.
    """

    weights: FloatArray
    table: NDArray[np.int64]
    squashed: bool
    low: FloatArray
    high: FloatArray

    @classmethod
    def from_policy(cls, policy: Any) -> ActorChain | None:
        """The chain of ``policy`` (an SB3 policy), or None where it is not one of
        flattened inputs, linear layers, ``tanh`` and ``ReLU`` (then only torch can act)."""
        import torch
        from stable_baselines3.common.distributions import (
            DiagGaussianDistribution,
            StateDependentNoiseDistribution,
        )
        from stable_baselines3.common.torch_layers import FlattenExtractor

        modules: list[Any]
        squash_tanh = False
        if hasattr(policy, "mlp_extractor"):  # PPO, A2C: the Gaussian's mean, clipped
            gaussian = (DiagGaussianDistribution, StateDependentNoiseDistribution)
            if policy.squash_output or not isinstance(policy.action_dist, gaussian):
                return None
            extractor = policy.pi_features_extractor
            modules = [*policy.mlp_extractor.policy_net, policy.action_net]
        elif hasattr(policy, "actor") and hasattr(policy.actor, "latent_pi"):  # SAC
            extractor = policy.actor.features_extractor
            modules = [*policy.actor.latent_pi, policy.actor.mu]
            squash_tanh = True  # the squashed Gaussian's mode
        elif hasattr(policy, "actor") and hasattr(policy.actor, "mu"):  # TD3 (ends in Tanh)
            extractor = policy.actor.features_extractor
            modules = list(policy.actor.mu)
        else:
            return None
        if not isinstance(extractor, FlattenExtractor) or not _flat_box(policy.observation_space):
            return None  # the observation is preprocessed (one-hot, images scaled ...)
        parts: list[FloatArray] = []
        rows: list[list[int]] = []
        offset = 0
        for module in modules:
            if isinstance(module, torch.nn.Linear):
                w = module.weight.detach().cpu().numpy().astype(np.float64)
                b = (
                    module.bias.detach().cpu().numpy().astype(np.float64)
                    if module.bias is not None
                    else np.zeros(w.shape[0])
                )
                rows.append([w.shape[0], w.shape[1], offset, offset + w.size, _IDENTITY])
                parts += [w.ravel(), b]
                offset += w.size + b.size
            elif isinstance(module, torch.nn.Tanh | torch.nn.ReLU) and rows:
                if rows[-1][4] != _IDENTITY:
                    return None
                rows[-1][4] = _TANH if isinstance(module, torch.nn.Tanh) else _RELU
            elif not isinstance(module, torch.nn.Identity):
                return None
        if not rows:
            return None
        if squash_tanh:
            if rows[-1][4] != _IDENTITY:
                return None
            rows[-1][4] = _TANH
        space = policy.action_space
        return cls(
            weights=np.concatenate(parts),
            table=np.asarray(rows, dtype=np.int64),
            squashed=bool(policy.squash_output),
            low=np.asarray(space.low, dtype=np.float64).ravel(),
            high=np.asarray(space.high, dtype=np.float64).ravel(),
        )

    def __call__(self, normalized: NDArray[np.float32]) -> NDArray[np.float32]:
        """The action (float32, the action space's shape flattened) for one normalised
        observation."""
        x = np.asarray(normalized, dtype=np.float64).ravel()
        if x.size != self.table[0, 1]:
            raise ValueError(f"the actor takes {self.table[0, 1]} values, got {x.size}")
        out = _forward(x, self.weights, self.table)
        if self.squashed:  # SB3's unscale_action
            out = self.low + 0.5 * (out + 1.0) * (self.high - self.low)
        return np.clip(out, self.low, self.high).astype(np.float32)
