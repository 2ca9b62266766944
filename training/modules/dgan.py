"""The DGAN network (Dong et al. 2020): a map CNN over the agent's raster crop, a shared LSTM over MLP-embedded
observed positions, a traffic-state MLP, their concatenation as node features, L stacked multi-head graph attention
layers masked by the attention-zone graph, and heads for class logits, anchor logits and per-anchor offsets.

Node features are agent-centric, so neighbour geometry travels on the edges: each edge carries the sender's position,
velocity and heading in the receiver's frame (``edge_features``), which enters both the attention score and the
message. Scores are clamped to ±20. Training runs the graph attention over the edge list (scatter-add); the exported
model (contract 3, :class:`PaddedDGAN`) runs the same attention, with the same weights, over each agent's padded
list of senders, which needs only gathers and dense reductions and which ONNX Runtime runs several times faster.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import torch
from torch import Tensor, nn

from training.modules.attention import GATLayer, NeighborGroups, neighbor_groups, padding_bias
from training.modules.scene import SCENE_STRIDE, MapEncoder, SceneMapEncoder

if TYPE_CHECKING:
    from training.modules.consensus import ConsensusEnsemble


@dataclass(frozen=True)
class ModelConfig:
    """Sizes of the network."""

    embed_dim: int = 32
    lstm_dim: int = 64
    state_dim_out: int = 64
    map_channels: int = 8  # width multiplier of the map CNN (sized to train on a CPU)
    map_dim: int = 64
    #: Residual blocks of the map CNN, after its first two strided convolutions: 2 (both), 1 (only the second, at a
    #: quarter of the first's pixels: about 1.3 MFLOP an agent less on a 48 × 47 crop) or 0 (three strided
    #: convolutions alone); issue 26.
    map_res_blocks: int = 2
    node_dim: int = 128
    gat_layers: int = 2
    gat_heads: int = 4
    head_dim: int = 256
    use_map: bool = True
    use_gat: bool = True
    use_edge_features: bool = True  # False: the attention sees no neighbour geometry (ablation)
    #: How the exported network arranges its attention, not what it computes (the same outputs, bit for bit on
    #: `hdmap`'s bundled scenes, to 1.4e-6 m on `apolloscape`'s): true splits the padded neighbours into two groups by
    #: degree inside the graph (:func:`neighbor_groups`), which pays where few agents have many senders (`hdmap`: -5 to
    #: -12% at 128-256 agents, some 70-95 µs a call for its fixed cost; docs/speed.md).
    neighbor_groups: bool = False
    #: The classes whose agents read the map (comma-separated names; "" = every class). Another class's agents get
    #: ``map_present`` 0 inside the network, as if their frame had no map (models with an optional map only; chosen on
    #: validation: `hdmap`'s vehicles are better without it, docs/results.md).
    map_classes: str = ""
    #: "crop": the map CNN runs over each agent's crop (its cost grows with the agents); "scene": its first stages run
    #: once over each window's scene raster and each agent reads their features at its crop's blocks
    #: (:mod:`training.modules.scene`; needs ``data.map_scene_px``; training only so far, issue 26).
    map_mode: str = "crop"


class DGAN(nn.Module):
    """Inputs and outputs follow the dgan model contract (``docs/model-contract.md``)."""

    map_gate: Tensor
    anchor_logit_scale: Tensor
    entropy_temperature: Tensor

    def __init__(
        self,
        cfg: ModelConfig,
        t_obs: int,
        t_f: int,
        state_dim: int,
        num_classes: int,
        num_anchors: int,
        map_hw: tuple[int, int] | None,
        map_optional: bool = False,
        map_gate: list[float] | None = None,
    ) -> None:
        super().__init__()
        self.cfg, self.t_f, self.k, self.num_classes = cfg, t_f, num_anchors, num_classes
        # Per class, whether its agents read the map (``map_classes``); derived from the configuration, not stored.
        self.register_buffer("map_gate", torch.tensor(map_gate or [1.0] * num_classes), persistent=False)
        self.gated = map_gate is not None and any(g != 1.0 for g in map_gate)
        # Each anchor's logit scale, 1/T of its class's block under a per-class temperature (``train.calibration =
        # "per_class"``, folded into the network so that the engine's decoding, at temperature 1, applies it); set
        # from the checkpoint by :meth:`set_anchor_logit_scale`.
        self.register_buffer("anchor_logit_scale", torch.ones(num_anchors), persistent=False)
        self.scaled = False
        # (a, b) of a temperature that follows the spread of each agent's anchor distribution (``train.calibration =
        # "entropy"``, :func:`entropy_tempered`), folded in the same way; set by :meth:`set_entropy_temperature`.
        self.register_buffer("entropy_temperature", torch.zeros(2), persistent=False)
        self.by_entropy = False
        self.embed = nn.Sequential(nn.Linear(3, cfg.embed_dim), nn.ReLU())
        self.lstm = nn.LSTM(cfg.embed_dim, cfg.lstm_dim, batch_first=True)
        self.state_mlp = nn.Sequential(
            nn.Linear(state_dim, cfg.state_dim_out),
            nn.ReLU(),
            nn.Linear(cfg.state_dim_out, cfg.state_dim_out),
            nn.ReLU(),
        )
        self.scene = cfg.map_mode == "scene"
        # Contract 13 (features kept with the map): (tile_px, halo_px), set by training.build.build_model from
        # data.map_scene_tile_px (None: rasters per call).
        self.kept_tiles: tuple[int, int] | None = None
        self.map_enc = map_encoder(cfg, map_hw)
        # An optional map (contract 2) also gives the node its map_present flag, and zeroes the map's features where
        # the flag is 0, so that "no map" is one well-defined input the network learns in map dropout.
        self.map_optional = map_optional and self.map_enc is not None
        if self.gated and self.scene:
            raise ValueError('model.map_classes is not served by model.map_mode = "scene" yet')
        if self.gated and not self.map_optional:
            raise ValueError("model.map_classes needs a model whose map is optional (map dropout, contract 2)")
        node_in = cfg.lstm_dim + cfg.state_dim_out + (cfg.map_dim if self.map_enc is not None else 0)
        node_in += 1 if self.map_optional else 0
        self.node = nn.Sequential(nn.Linear(node_in, cfg.node_dim), nn.ReLU())
        self.gat = nn.ModuleList(
            [GATLayer(cfg.node_dim, cfg.gat_heads, 6) for _ in range(cfg.gat_layers)] if cfg.use_gat else []
        )
        head_in = cfg.node_dim * (2 if cfg.use_gat else 1)
        self.trunk = nn.Sequential(
            nn.Linear(head_in, cfg.head_dim), nn.ReLU(), nn.Linear(cfg.head_dim, cfg.head_dim), nn.ReLU()
        )
        self.class_head = nn.Linear(cfg.head_dim, num_classes)
        self.anchor_head = nn.Linear(cfg.head_dim, num_anchors)
        self.offset_head = nn.Linear(cfg.head_dim, num_anchors * t_f * 2)

    def encode(
        self,
        trajectory: Tensor,
        trajectory_mask: Tensor,
        state: Tensor,
        map: Tensor | None,
        map_present: Tensor | None,
        *,
        scene: tuple[Tensor, ...] | None = None,
    ) -> Tensor:
        """Node features: the trajectory LSTM, the traffic-state MLP and the map CNN, concatenated and projected.
        With ``model.map_mode = "scene"``, ``map`` is the frames' scene rasters and ``scene`` their agents' grids and
        each agent's slot (``map_grid``, ``map_slot``: :class:`~training.modules.scene.SceneMapEncoder`); with one
        tensor, ``scene`` each agent's reading of the kept features (contract 13: ``map_patches``; ``map``, the tiles
        to compute, gives the fourth output, :meth:`tile_rows`)."""
        x = torch.cat([trajectory, trajectory_mask.unsqueeze(-1)], dim=-1)
        _, (h_n, _) = self.lstm(self.embed(x))
        parts = [h_n[-1], self.state_mlp(state)]
        if self.map_enc is not None:
            assert map is not None, "this model has a map branch"
            if self.gated:  # the state's last C columns are the agent's one-hot class
                assert map_present is not None, "this model's map is optional: it takes map_present"
                reads = state[:, -self.num_classes :] @ self.map_gate.to(state.dtype)
                map_present = map_present * reads
                features = self._readers_map(map, reads)
            elif self.scene and scene is not None and len(scene) == 1:
                assert isinstance(self.map_enc, SceneMapEncoder)
                features = self.map_enc.forward_kept(scene[0])
            elif self.scene:
                assert scene is not None, "a scene map encoder takes map_grid and map_slot"
                features = self.map_enc(map, *scene)
            else:
                features = self.map_enc(map)
            if self.map_optional:
                assert map_present is not None, "this model's map is optional: it takes map_present"
                present = map_present.unsqueeze(-1)
                parts += [features * present, present]
            else:
                parts.append(features)
        out: Tensor = self.node(torch.cat(parts, dim=-1))
        return out

    def _readers_map(self, map: Tensor, reads: Tensor) -> Tensor:
        """The map CNN's features of the agents whose class reads the map (``reads`` 1), zeros for the others: only
        their crops go through it, so a frame's cost follows its readers (none: an empty batch, which PyTorch and ONNX
        Runtime both run). BatchNorm in eval mode works row by row, so each row's features are those of a pass over
        every crop."""
        assert self.map_enc is not None
        rows = torch.nonzero(reads > 0).reshape(-1)
        sub = self.map_enc(map[rows])
        out = torch.zeros(map.shape[0], sub.shape[1], dtype=sub.dtype, device=sub.device)
        return out.index_put((rows,), sub)

    def heads(self, p: Tensor, v: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        z = self.trunk(torch.cat([p, v], dim=-1)) if self.cfg.use_gat else self.trunk(v + p)
        offsets = self.offset_head(z).view(-1, self.k, self.t_f, 2)
        anchor_logits = self.anchor_head(z)
        if self.scaled:
            anchor_logits = anchor_logits * self.anchor_logit_scale.to(anchor_logits.dtype)
        if self.by_entropy:
            ab = self.entropy_temperature.to(anchor_logits.dtype)
            anchor_logits = entropy_tempered(anchor_logits, self.num_classes, ab[0], ab[1])
        return self.class_head(z), anchor_logits, offsets

    def set_anchor_logit_scale(self, scale: list[float] | None) -> None:
        """Scales each anchor's logit (``None``: none), as a per-class temperature folded into the network does."""
        values = [1.0] * self.k if scale is None else [float(x) for x in scale]
        if len(values) != self.k or not all(0.0 < x < float("inf") for x in values):
            raise ValueError(f"anchor_logit_scale needs {self.k} positive finite values, got {scale}")
        self.anchor_logit_scale.copy_(torch.tensor(values))
        self.scaled = scale is not None

    def set_entropy_temperature(self, ab: list[float] | None) -> None:
        """Divides each agent's anchor logits by exp(a + b · H) (:func:`entropy_tempered`; ``None``: not)."""
        if ab is not None and (len(ab) != 2 or not all(abs(float(x)) < float("inf") for x in ab)):
            raise ValueError(f"anchor_entropy_temperature needs two finite values (a, b), got {ab}")
        self.entropy_temperature.copy_(torch.tensor([0.0, 0.0] if ab is None else [float(x) for x in ab]))
        self.by_entropy = ab is not None

    def forward(
        self,
        trajectory: Tensor,
        trajectory_mask: Tensor,
        state: Tensor,
        edge_index: Tensor,
        edge_features: Tensor,
        map: Tensor | None = None,
        map_present: Tensor | None = None,
        map_grid: Tensor | None = None,
        map_slot: Tensor | None = None,
        map_patches: Tensor | None = None,
    ) -> tuple[Tensor, ...]:
        """Class logits, anchor logits and offsets (and with kept features, contract 13, the new tiles' rows)."""
        scene = scene_inputs(map_grid, map_slot, map_patches)
        v = self.encode(trajectory, trajectory_mask, state, map, map_present, scene=scene)
        if not self.cfg.use_edge_features:
            edge_features = edge_features * 0.0
        p = v
        for layer in self.gat:
            p = layer(p, edge_index, edge_features)
        if not self.cfg.use_gat:
            # The contract's edge inputs stay in the exported graph (an exporter drops unused inputs).
            p = (edge_features.sum() + edge_index.sum().to(v.dtype)) * 0.0
        return self.heads(p, v) + self._kept_out(map, scene)

    def tile_rows(self, tiles: Tensor) -> Tensor:
        """The features of tiles of the map as the engine keeps them (contract 13:
        :meth:`~training.modules.scene.SceneMapEncoder.tile_rows`)."""
        assert self.kept_tiles is not None, "kept features need data.map_scene_tile_px"
        assert isinstance(self.map_enc, SceneMapEncoder)
        return self.map_enc.tile_rows(tiles, *self.kept_tiles)

    def _kept_out(self, map: Tensor | None, scene: tuple[Tensor, ...] | None) -> tuple[Tensor, ...]:
        """The rows of the tiles ``map`` as a fourth output where the map's features are kept (contract 13)."""
        if map is None or scene is None or len(scene) != 1:
            return ()
        return (self.tile_rows(map),)

    def forward_padded(
        self,
        trajectory: Tensor,
        trajectory_mask: Tensor,
        state: Tensor,
        neighbor_index: Tensor,
        neighbor_mask: Tensor,
        neighbor_features: Tensor,
        map: Tensor | None = None,
        map_present: Tensor | None = None,
        map_grid: Tensor | None = None,
        map_slot: Tensor | None = None,
        map_patches: Tensor | None = None,
    ) -> tuple[Tensor, ...]:
        """:meth:`forward` on the padded neighbour layout (contract 3): the same outputs for the same graph."""
        scene = scene_inputs(map_grid, map_slot, map_patches)
        v = self.encode(trajectory, trajectory_mask, state, map, map_present, scene=scene)
        if not self.cfg.use_edge_features:
            neighbor_features = neighbor_features * 0.0
        p = v
        # A column of ones: each layer's first edge product carries its bias (GATLayer.forward_padded).
        ones = torch.ones_like(neighbor_features[..., :1])
        features = torch.cat([neighbor_features, ones], dim=-1)
        groups = (
            neighbor_groups(neighbor_index, neighbor_mask, features)
            if self.cfg.neighbor_groups
            else NeighborGroups((neighbor_index, padding_bias(neighbor_mask), features))
        )
        for layer in self.gat:
            assert isinstance(layer, GATLayer)
            p = layer.forward_padded(p, groups)
        if not self.cfg.use_gat:
            unused = neighbor_features.sum() + neighbor_index.sum().to(v.dtype) + neighbor_mask.sum()
            p = unused * 0.0
        return self.heads(p, v) + self._kept_out(map, scene)


def scene_inputs(grid: Tensor | None, slot: Tensor | None, patches: Tensor | None) -> tuple[Tensor, ...] | None:
    """A scene model's reading inputs: the grids and slots of contract 12, the agents' readings of the kept features
    of contract 13, or None (a crop model)."""
    if patches is not None:
        return (patches,)
    return None if grid is None or slot is None else (grid, slot)


def map_encoder(cfg: ModelConfig, map_hw: tuple[int, int] | None) -> nn.Module | None:
    """The map CNN of ``model.map_mode``: over each agent's ``map_hw`` crop, or over the scene's raster read at the
    crop's blocks (:class:`~training.modules.scene.SceneMapEncoder`); None without a map."""
    if cfg.map_mode not in ("crop", "scene"):
        raise ValueError(f'model.map_mode must be "crop" or "scene", got {cfg.map_mode!r}')
    if not (cfg.use_map and map_hw):
        return None
    if cfg.map_mode == "scene":
        grid_hw = (math.ceil(map_hw[0] / SCENE_STRIDE), math.ceil(map_hw[1] / SCENE_STRIDE))
        return SceneMapEncoder(cfg.map_channels, cfg.map_dim, grid_hw, cfg.map_res_blocks)
    return MapEncoder(cfg.map_channels, cfg.map_dim, *map_hw, res_blocks=cfg.map_res_blocks)


def entropy_tempered(anchor_logits: Tensor, classes: int, a: Tensor | float, b: Tensor | float) -> Tensor:
    """``(N, K)`` anchor logits divided, per agent and class block, by T = exp(a + b · H), H the entropy (nats) of
    the agent's softmax over that class's anchors at T = 1 (the blocks: ``classes`` equal runs of anchors,
    ``training.anchors``). With b > 0 a spread distribution is flattened and a peaked one sharpened, which mends the
    S-shaped reliability one temperature cannot (``training.calibrate``, ``"entropy"``)."""
    n, k = anchor_logits.shape
    blocks = anchor_logits.reshape(n, classes, k // classes)
    logp = torch.log_softmax(blocks, dim=2)
    h = -(logp.exp() * logp).sum(dim=2, keepdim=True)
    return (blocks / torch.exp(a + b * h)).reshape(n, k)


class PaddedDGAN(nn.Module):
    """A trained :class:`DGAN` whose ``forward`` takes the padded neighbour layout: what the exporter traces."""

    def __init__(self, model: DGAN | ConsensusEnsemble, names: list[str] | None = None) -> None:
        super().__init__()
        self.model = model
        #: The inputs' names, in the order ``forward`` takes them (a scene model's map_present may be absent).
        self.names = names

    def forward(self, *inputs: Tensor) -> tuple[Tensor, ...]:
        if self.names is None:
            return self.model.forward_padded(*inputs)
        return self.model.forward_padded(**dict(zip(self.names, inputs, strict=True)))
