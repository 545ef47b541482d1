"""The paper's network: a PointNet encoder of the partial cloud, and an MLP on its feature and the design.

PointNet (the authors' ``PointNetEncoder``, no T-Net): pointwise Conv1d 3→64→128→128 with ReLU between
them, a max-pool over the points, the feature times a learnable scalar (``pc_scale``). MLP (the
authors' ``MLPModel``): [feature, 22 z(ln E), COM (3), z(density)(, frame (7))] → ``depth`` layers of
``hidden`` with BatchNorm, ReLU and dropout, then ``hidden // 2`` (512) likewise, then 10 outputs, and
with :attr:`ModelConfig.success_head` an 11th: the logit of the success probability.

The two halves are separate calls so that a cloud's feature is computed once per pose and shared by
its samples (:meth:`GraspNet.forward` takes the unique clouds and an index per sample).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import torch
from torch import nn

from mjcodesign.errors import DesignError
from mjcodesign.surrogate.data import N_OUTPUTS

__all__ = ["GraspNet", "ModelConfig"]

_DESIGN_INPUTS = 22 + 3 + 1  # z(ln E), COM, z(density)
_FRAME_INPUTS = 7  # world vertical (3), cloud centre (3) and radius (1): data.frame_inputs


@dataclass(frozen=True, kw_only=True)
class ModelConfig:
    """Widths and depths of :class:`GraspNet`; the defaults are the paper's network."""

    point_widths: tuple[int, ...] = (64, 128, 128)
    """Output channels of the pointwise Conv1d layers; the last is the feature size."""
    hidden: int = 1024
    """Width of the MLP's hidden layers."""
    depth: int = 5
    """Hidden layers of width ``hidden``."""
    penultimate: int = 512
    """Width of the layer before the output (the authors' ``hidden // 2``)."""
    dropout: float = 0.3
    frame_inputs: bool = True
    """Feed the pose's frame to the MLP: the world's vertical in the gripper frame (3), and the cloud's
    centre (3) and radius (1) that the normalisation takes out of the PointNet's input. The authors'
    data are in a y-up world frame, where gravity is implicit; ours are in the gripper frame (top and
    side grasps), and an object's weight needs its size. False: the paper's inputs (154 wide)."""
    success_head: bool = False
    """An 11th output: the logit of the grasp's success probability, trained on the dataset's
    ``success_p`` (its 0/1 success without one). False: the paper's 10 outputs (``mjcodesign train``
    adds the head unless ``--success-weight 0``; a record without the key has none)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "point_widths", tuple(int(w) for w in self.point_widths))
        sizes = (*self.point_widths, self.hidden, self.depth, self.penultimate)
        if not self.point_widths or any(int(v) < 1 for v in sizes):
            raise DesignError(f"network widths and depth must be integers >= 1, got {self}")
        if not (0.0 <= self.dropout < 1.0):
            raise DesignError(f"dropout must be in [0, 1), got {self.dropout}")
        if not isinstance(self.success_head, bool):
            raise DesignError(f"success_head must be True or False, got {self.success_head!r}")

    @property
    def feature_size(self) -> int:
        """Size of the cloud feature."""
        return self.point_widths[-1]

    @property
    def design_inputs(self) -> int:
        """Inputs of the MLP besides the cloud feature."""
        return _DESIGN_INPUTS + (_FRAME_INPUTS if self.frame_inputs else 0)

    @property
    def outputs(self) -> int:
        """Outputs of the network: the 10 of the data, and the success logit with a head."""
        return N_OUTPUTS + int(self.success_head)

    def as_dict(self) -> dict:
        """JSON-ready fields."""
        d = dataclasses.asdict(self)
        d["point_widths"] = list(self.point_widths)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> ModelConfig:
        """Inverse of :meth:`as_dict`; unknown keys raise :class:`DesignError`, missing ones take their default."""
        names = {f.name for f in dataclasses.fields(cls)}
        if set(d) - names:
            raise DesignError(f"unknown model settings {sorted(set(d) - names)}")
        return cls(**d)


class PointNet(nn.Module):
    """Pointwise Conv1d layers with ReLU between them, max-pooled over the points.

    The layers are ``Conv1d(·, ·, 1)`` modules (the authors' parameters and checkpoint keys), applied
    as one matrix product over all points: the same function, and on this CPU 25% faster forward
    and backward than the convolution kernel (measured on 16 clouds of 1024 points, 46 vs 61 ms).
    """

    def __init__(self, widths: tuple[int, ...]):
        super().__init__()
        layers: list[nn.Module] = []
        prev = 3
        for i, w in enumerate(widths):
            layers.append(nn.Conv1d(prev, w, 1))
            if i < len(widths) - 1:
                layers.append(nn.ReLU())
            prev = w
        self.net = nn.Sequential(*layers)

    def forward(self, clouds: torch.Tensor) -> torch.Tensor:
        """Features (P, F) of clouds (P, 3, N)."""
        h = clouds.transpose(1, 2)
        for layer in self.net:
            if isinstance(layer, nn.Conv1d):
                h = nn.functional.linear(h, layer.weight.squeeze(-1), layer.bias)
            else:
                h = layer(h)
        return h.amax(dim=1)


class Dropout(nn.Module):
    """Inverted dropout, as ``nn.Dropout``, with its mask drawn as ``rand >= p``.

    ``nn.Dropout`` draws the mask with ``bernoulli_``, which on this CPU takes 7.2 ms per 512×1024
    activation against 3.1 ms for this; the MLP's six dropouts were 14% of a training step.
    """

    def __init__(self, p: float):
        super().__init__()
        self.p = float(p)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if not self.training or self.p == 0.0:
            return x
        keep = torch.rand(x.shape, device=x.device) >= self.p
        return x * keep * (1.0 / (1.0 - self.p))

    def extra_repr(self) -> str:
        return f"p={self.p}"


def _block(n_in: int, n_out: int, dropout: float) -> list[nn.Module]:
    return [nn.Linear(n_in, n_out), nn.BatchNorm1d(n_out), nn.ReLU(), Dropout(dropout)]


class GraspNet(nn.Module):
    """PointNet + MLP (module docstring)."""

    def __init__(self, config: ModelConfig | None = None):
        super().__init__()
        c = config or ModelConfig()
        self.config = c
        self.pointnet = PointNet(c.point_widths)
        self.pc_scale = nn.Parameter(torch.ones(1))
        layers = _block(c.feature_size + c.design_inputs, c.hidden, c.dropout)
        for _ in range(c.depth - 1):
            layers += _block(c.hidden, c.hidden, c.dropout)
        layers += _block(c.hidden, c.penultimate, c.dropout)
        layers.append(nn.Linear(c.penultimate, c.outputs))
        self.mlp = nn.Sequential(*layers)

    def encode(self, clouds: torch.Tensor) -> torch.Tensor:
        """Cloud features (P, F) of normalised clouds (P, 3, N), scaled by ``pc_scale``."""
        return self.pc_scale * self.pointnet(clouds)

    def head(self, features: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        """Outputs (B, 10 or 11) from per-sample features (B, F) and inputs (B, D)."""
        return self.mlp(torch.cat([features, x], dim=1))

    def forward(self, clouds: torch.Tensor, pose_of: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        """Outputs (B, 10 or 11): unique clouds (U, 3, N), each sample's cloud row (B,), inputs (B, D)."""
        return self.head(self.encode(clouds)[pose_of], x)
