"""The map CNNs: over each agent's crop (:class:`MapEncoder`), or shared by every agent of a window
(:class:`SceneMapEncoder`, ``model.map_mode = "scene"``; issue 26, the paper's own design).

The crop encoder runs its whole CNN over each agent's crop, so the map's
cost grows with the agents. Here its first two stages (the strided stem, the first residual block, the second strided
convolution and residual block: everything at 1/2 and 1/4 of the crop's pixels) run once over the window's scene
raster (:func:`dgan.scene_raster`), and each agent reads the quarter-resolution features at the centres of its crop's
4 × 4 blocks (:func:`dgan.crop_grid`, bilinear ``grid_sample``); its last strided convolution and projection stay per
agent, as in the crop encoder. Per agent that leaves about a tenth of the crop encoder's operations.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn


class ResBlock(nn.Module):
    def __init__(self, c: int) -> None:
        super().__init__()
        self.body = nn.Sequential(
            nn.Conv2d(c, c, 3, padding=1),
            nn.BatchNorm2d(c),
            nn.ReLU(),
            nn.Conv2d(c, c, 3, padding=1),
            nn.BatchNorm2d(c),
        )

    def forward(self, x: Tensor) -> Tensor:
        out: Tensor = torch.relu(x + self.body(x))
        return out


class MapEncoder(nn.Module):
    """A small ResNet over the ``(3, H, W)`` crop; the flattened 4× downsampled map keeps where things are."""

    def __init__(self, c: int, out: int, h: int, w: int, res_blocks: int = 2) -> None:
        super().__init__()
        if not 0 <= res_blocks <= 2:
            raise ValueError(f"model.map_res_blocks must be 0, 1 or 2, got {res_blocks}")
        blocks = (
            ResBlock(c) if res_blocks == 2 else nn.Identity(),
            ResBlock(2 * c) if res_blocks >= 1 else nn.Identity(),
        )
        self.net = nn.Sequential(
            nn.Conv2d(3, c, 3, stride=2, padding=1),
            nn.BatchNorm2d(c),
            nn.ReLU(),
            blocks[0],
            nn.Conv2d(c, 2 * c, 3, stride=2, padding=1),
            nn.BatchNorm2d(2 * c),
            nn.ReLU(),
            blocks[1],
            nn.Conv2d(2 * c, 2 * c, 3, stride=2, padding=1),
            nn.ReLU(),
        )
        hh, ww = h, w
        for _ in range(3):
            hh, ww = (hh + 1) // 2, (ww + 1) // 2
        self.proj = nn.Sequential(nn.Flatten(), nn.Linear(2 * c * hh * ww, out), nn.ReLU())

    def forward(self, x: Tensor) -> Tensor:
        out: Tensor = self.proj(self.net(x))
        return out


#: The scene CNN's downsampling: each agent reads it at the centres of its crop's blocks of this many pixels a side.
SCENE_STRIDE = 4
#: The least raster side a scene model asks of the engine (``map.scene.min_px``): the engine's rasters just hold the
#: crops (zara1's validation top-1 with 32, 64 and 128: 0.381077, 0.381077, 0.381076 m; docs/results.md), while
#: training draws each window's raster at ``data.map_scene_px``.
SCENE_MIN_PX = 32
#: A training window's raster side where ``data.map_scene_px`` leaves it unset (a scene model's spec, e.g. a bundled
#: one's, with a data configuration of its own).
SCENE_TRAIN_PX = 128


def scene_halo_px(res_blocks: int) -> int:
    """The pixels a kept tile's raster needs around it (contract 13) so that its features are those of a map without
    edges: the scene CNN's reach (3 × 3 convolutions: the stem 1 pixel, the first residual block 4, the second strided
    convolution 2, the second block 8), rounded up to the stride."""
    reach = 1 + (4 if res_blocks >= 2 else 0) + 2 + (8 if res_blocks >= 1 else 0)
    return -(-reach // SCENE_STRIDE) * SCENE_STRIDE


class SceneMapEncoder(nn.Module):
    """``(W, 3, S, S)`` scene rasters, ``(A, gh, gw, 2)`` crop grids and ``(A,)`` each agent's window → ``(A, out)``."""

    def __init__(self, c: int, out: int, grid_hw: tuple[int, int], res_blocks: int = 2) -> None:
        super().__init__()
        if not 0 <= res_blocks <= 2:
            raise ValueError(f"model.map_res_blocks must be 0, 1 or 2, got {res_blocks}")
        self.scene = nn.Sequential(
            nn.Conv2d(3, c, 3, stride=2, padding=1),
            nn.BatchNorm2d(c),
            nn.ReLU(),
            ResBlock(c) if res_blocks == 2 else nn.Identity(),
            nn.Conv2d(c, 2 * c, 3, stride=2, padding=1),
            nn.BatchNorm2d(2 * c),
            nn.ReLU(),
            ResBlock(2 * c) if res_blocks >= 1 else nn.Identity(),
        )
        self.agent = nn.Sequential(nn.Conv2d(2 * c, 2 * c, 3, stride=2, padding=1), nn.ReLU())
        self.grid_hw = grid_hw
        hh, ww = (math.ceil(x / 2) for x in grid_hw)
        self.proj = nn.Sequential(nn.Flatten(), nn.Linear(2 * c * hh * ww, out), nn.ReLU())

    def forward(self, scene: Tensor, grid: Tensor, slot: Tensor) -> Tensor:
        patches = read_slots(self.scene(scene), grid, slot)
        out: Tensor = self.proj(self.agent(patches))
        return out

    def tile_rows(self, tiles: Tensor, tile: int, halo: int) -> Tensor:
        """Contract 13: the features of tiles of the map, ``(T, 3, P, P)`` rasters of ``tile`` pixels and ``halo``
        more each side, as ``(T · t², C)`` rows (each tile's ``t × t`` without the halo's, row-major): what the engine
        keeps with the map (``dgan_core::kept``) and reads each agent's blocks from (:func:`dgan.read_kept`)."""
        f = self.scene(tiles)
        h, t = halo // SCENE_STRIDE, tile // SCENE_STRIDE
        rows: Tensor = f[:, :, h : h + t, h : h + t].permute(0, 2, 3, 1).reshape(-1, f.shape[1])
        return rows

    def forward_kept(self, patches: Tensor) -> Tensor:
        """Contract 13: ``(A, out)`` from each agent's reading of the kept features ``(A, C, gh, gw)``
        (``map_patches``; the engine reads them from the rows of :meth:`tile_rows`)."""
        out: Tensor = self.proj(self.agent(patches))
        return out


def read_slots(features: Tensor, grid: Tensor, slot: Tensor) -> Tensor:
    """``(A, C, gh, gw)``: each agent's grid read bilinearly from its own frame's ``(F, C, h, w)`` features as
    ``grid_sample`` reads (``align_corners=False``, zeros outside), ``grid`` ``(F, M, gh, gw, 2)`` each frame's agents
    padded to M and ``slot`` ``(A,)`` each agent's row of it flattened: the engine's layout (contract 12), in training
    and in the exported graph alike. Written as four gathers of the features' rows and their weighted sum rather than
    ``grid_sample``, which ONNX Runtime runs 2.3 times slower here (docs/speed.md); the same reads to float rounding."""
    f, c, h, w = features.shape
    m, gh, gw = grid.shape[1:4]
    g = grid.reshape(f * m, gh * gw, 2).index_select(0, slot)  # (A, P, 2)
    frame = torch.div(slot, m, rounding_mode="floor").unsqueeze(1)  # (A, 1)
    u = (g[..., 0] + 1) * (w / 2) - 0.5  # pixel coordinates, centres at integers
    v = (g[..., 1] + 1) * (h / 2) - 0.5
    u0, v0 = torch.floor(u), torch.floor(v)
    du, dv = u - u0, v - v0
    rows = features.permute(0, 2, 3, 1).reshape(f * h * w, c)
    out = torch.zeros(g.shape[0], gh * gw, c, dtype=features.dtype, device=features.device)
    for i, wu in ((0, 1 - du), (1, du)):
        for j, wv in ((0, 1 - dv), (1, dv)):
            uu, vv = u0 + i, v0 + j
            inside = ((uu >= 0) & (uu <= w - 1) & (vv >= 0) & (vv <= h - 1)).to(features.dtype)
            at = frame * (h * w) + vv.clamp(0, h - 1).long() * w + uu.clamp(0, w - 1).long()
            out = out + (wu * wv * inside).unsqueeze(-1) * rows[at]
    return out.permute(0, 2, 1).reshape(-1, c, gh, gw)
