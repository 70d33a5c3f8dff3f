"""PyTorch twin of :class:`~safelane.planners.nn.MLPPlanner`, for training only (``pip install 'safelane[train]'``).

:class:`TorchPlanner` computes exactly what :meth:`MLPPlanner.predict` computes (normalisation, two MLPs, tanh
scaling into the action bounds) in float32; :func:`to_planner` / :func:`from_planner` convert both ways without
loss. This module imports PyTorch at import time; import it lazily (see :func:`require_torch`).
"""

from __future__ import annotations

import math

import numpy as np

from ..planners.nn import HEADS, MLPPlanner


def require_torch():
    """Import PyTorch or fail with an install hint."""
    try:
        import torch
    except ImportError as exc:
        raise ImportError("training needs PyTorch: pip install 'safelane[train]'") from exc
    return torch


torch = require_torch()
nn = torch.nn


def _mlp(n_in: int, hidden: tuple[int, ...], activation: str) -> nn.Sequential:
    act = {"tanh": nn.Tanh, "relu": nn.ReLU}[activation]
    layers: list[nn.Module] = []
    for width in hidden:
        layers += [nn.Linear(n_in, width), act()]
        n_in = width
    layers.append(nn.Linear(n_in, 1))
    return nn.Sequential(*layers)


def init_weights(module: nn.Module, generator: torch.Generator) -> None:
    """Re-draw every ``nn.Linear`` with PyTorch's default distributions from an explicit ``generator``.

    ``U(±1/sqrt(fan_in))`` for weights (``kaiming_uniform_(a=sqrt(5))``) and biases, layer by layer in module
    order — the same draws ``nn.Linear`` makes from the global generator, without touching it.
    """
    with torch.no_grad():
        for layer in module.modules():
            if isinstance(layer, nn.Linear):
                bound = 1.0 / math.sqrt(layer.in_features)
                layer.weight.uniform_(-bound, bound, generator=generator)
                layer.bias.uniform_(-bound, bound, generator=generator)


class TorchPlanner(nn.Module):
    """Raw features ``(B, F)`` → bounded actions ``(B, 2)`` [m/s²] (``a_x``, ``a_y``), float32.

    Args:
        mean, std: feature normalisation ``(F,)``.
        hidden: widths of the hidden layers of each network.
        activation: ``"tanh"`` or ``"relu"``.
        bounds: per head, ``(low, high)`` [m/s²].
    """

    def __init__(self, mean, std, hidden: tuple[int, ...], activation: str, bounds: dict[str, tuple[float, float]]):
        super().__init__()
        self.activation, self.hidden = activation, tuple(hidden)
        self.bounds = {h: (float(lo), float(hi)) for h, (lo, hi) in bounds.items()}
        # float64 copies keep the NumPy planner's normalisation exact through a round trip
        self.mean64, self.std64 = np.asarray(mean, np.float64).copy(), np.asarray(std, np.float64).copy()
        self.register_buffer("mean", torch.as_tensor(np.asarray(mean), dtype=torch.float32))
        self.register_buffer("std", torch.as_tensor(np.asarray(std), dtype=torch.float32))
        lo = [self.bounds[h][0] for h in HEADS]
        hi = [self.bounds[h][1] for h in HEADS]
        self.register_buffer("out_mid", 0.5 * (torch.tensor(lo) + torch.tensor(hi)))
        self.register_buffer("out_half", 0.5 * (torch.tensor(hi) - torch.tensor(lo)))
        self.nets = nn.ModuleDict({h: _mlp(len(mean), self.hidden, activation) for h in HEADS})

    def forward(self, x):
        z = (x - self.mean) / self.std
        out = torch.cat([self.nets[h](z) for h in HEADS], dim=1)
        return self.out_mid + self.out_half * torch.tanh(out)


def to_planner(module: TorchPlanner, metadata: dict | None = None) -> MLPPlanner:
    """The NumPy planner with ``module``'s weights (copied; float32)."""
    layers = {}
    for head in HEADS:
        linears = [m for m in module.nets[head] if isinstance(m, nn.Linear)]
        layers[head] = tuple(
            (m.weight.detach().cpu().numpy().T.astype(np.float32).copy(), m.bias.detach().cpu().numpy().copy())
            for m in linears
        )
    return MLPPlanner(
        layers=layers,
        mean=module.mean64.copy(),
        std=module.std64.copy(),
        bounds=dict(module.bounds),
        activation=module.activation,
        metadata=dict(metadata or {}),
    )


def from_planner(planner: MLPPlanner) -> TorchPlanner:
    """A :class:`TorchPlanner` with ``planner``'s weights (hidden widths must be equal across heads)."""
    hidden = tuple(w.shape[1] for w, _ in planner.layers[HEADS[0]][:-1])
    module = TorchPlanner(planner.mean, planner.std, hidden, planner.activation, planner.bounds)
    with torch.no_grad():
        for head in HEADS:
            linears = [m for m in module.nets[head] if isinstance(m, nn.Linear)]
            if len(linears) != len(planner.layers[head]):
                raise ValueError(f"head {head}: {len(planner.layers[head])} layers, expected {len(linears)}")
            for m, (w, b) in zip(linears, planner.layers[head], strict=True):
                if m.weight.shape != (w.shape[1], w.shape[0]):
                    raise ValueError(f"head {head}: layer shape {w.shape} differs from the first head's")
                m.weight.copy_(torch.from_numpy(np.ascontiguousarray(w.T)))
                m.bias.copy_(torch.from_numpy(b))
    return module
