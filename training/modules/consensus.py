"""Several trained :class:`~training.modules.dgan.DGAN` runs of one configuration as one network under the same
contract (``training.ensemble``): the consensus of their most probable modes."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor, nn

#: Where ``map_patches`` falls among :meth:`DGAN.forward`'s (and ``forward_padded``'s) positional inputs.
PATCHES_AT = 10


class ConsensusEnsemble(nn.Module):
    """Several :class:`DGAN` runs of one configuration (seeds) as one network under the same contract: the first
    member's outputs, except that in the block of anchors of the agent's most probable class (by the first member's
    class logits) its most probable mode is replaced by the mean of every member's most probable mode of that class
    (each member's anchor + offset, in the agent frame relative to the kinematic prior, which the members share). The
    engine ranks modes within a class by the anchor logits, which stay the first member's, so its top mode of that
    class is the consensus; the other modes are the first member's.

    Averaging the members' most probable futures cancels much of the run-to-run spread (``training.studies.seed``).

    ``top_scale (C,)``: per class, how much of the consensus mode's residual over the prior is kept
    (``prior + s_c · residual``; 1 by default, 0 is the prior itself), fitted on validation by
    ``training.ensemble.fit_top_scale`` for classes whose top mode the network refines for the worse.
    """

    anchors: Tensor
    top_scale: Tensor

    def __init__(
        self, members: Sequence[nn.Module], anchors: list[Tensor], classes: int, top_scale: list[float] | None = None
    ) -> None:
        super().__init__()
        if not members or len(members) != len(anchors):
            raise ValueError("an ensemble needs one anchor set per member, and at least one member")
        shape = anchors[0].shape
        if any(a.shape != shape for a in anchors) or shape[0] % classes:
            raise ValueError(f"every member needs the same anchors per class; got shapes {[a.shape for a in anchors]}")
        self.members = nn.ModuleList(members)
        self.classes, self.per_class = classes, shape[0] // classes
        # (M, C, Kc, T, 2): anchors grouped by class, as the contract stores them.
        self.register_buffer("anchors", torch.stack([a.reshape(classes, self.per_class, *shape[1:]) for a in anchors]))
        scale = [1.0] * classes if top_scale is None else [float(x) for x in top_scale]
        if len(scale) != classes or not all(0.0 <= x <= 1.0 for x in scale):
            raise ValueError(f"top_scale needs one value in [0, 1] per class ({classes}); got {top_scale}")
        self.register_buffer("top_scale", torch.tensor(scale, dtype=torch.float32))

    def combine(self, outs: list[tuple[Tensor, Tensor, Tensor]]) -> tuple[Tensor, Tensor, Tensor]:
        cl0, al0, off0 = outs[0]
        n, c, kc = al0.shape[0], self.classes, self.per_class
        tail = off0.shape[2:]
        # Only in the block of the most probable class (the class is an input, so p(c) is all but one-hot there):
        # the other blocks keep the first member's modes, which vary continuously with the inputs, while a block's
        # top anchor can switch between near-equal logits. Each member's most probable mode of that class is
        # gathered alone and the first member's is overwritten by one scatter (the same numbers as masking the
        # whole (N, K, T, 2) tensor, at a fraction of its memory traffic).
        top_class = cl0.argmax(-1)  # (N,)
        picks = []  # per member: the mode's index among all K (N,), its anchor and itself (N, T, 2)
        for m, (_, al, off) in enumerate(outs):
            best = al.reshape(n, c, kc).argmax(-1).gather(1, top_class.unsqueeze(1)).squeeze(1)  # (N,)
            k = top_class * kc + best
            anchor = self.anchors[m].reshape(c * kc, *tail)[k]
            picks.append((k, anchor, anchor + off.gather(1, k.reshape(n, 1, 1, 1).expand(n, 1, *tail)).squeeze(1)))
        # (N, T, 2), relative to the prior; scaled per class towards it.
        consensus = (
            torch.stack([top for _, _, top in picks]).mean(0) * self.top_scale.to(off0.dtype)[top_class][:, None, None]
        )
        first, first_anchor, _ = picks[0]
        at = first.reshape(n, 1, 1, 1).expand(n, 1, *tail)
        return cl0, al0, off0.scatter(1, at, (consensus - first_anchor).unsqueeze(1))

    def forward(self, *inputs: Tensor | None, **named: Tensor | None) -> tuple[Tensor, ...]:
        return self._run("forward", inputs, named)

    def forward_padded(self, *inputs: Tensor | None, **named: Tensor | None) -> tuple[Tensor, ...]:
        return self._run("forward_padded", inputs, named)

    def _run(
        self, method: str, inputs: tuple[Tensor | None, ...], named: dict[str, Tensor | None]
    ) -> tuple[Tensor, ...]:
        """Every member's ``method`` and their :meth:`combine`. Members that keep their map's features (contract 13)
        keep them side by side: the kept rows are the members' rows concatenated by channel (a fourth output), and
        each member reads its own block of ``map_patches``' channels."""
        patches = named.get("map_patches")
        if patches is None and len(inputs) > PATCHES_AT:
            raise ValueError("a consensus takes map_patches by name")
        if patches is not None and patches.shape[1] % len(self.members):
            raise ValueError(f"map_patches' {patches.shape[1]} channels do not split over {len(self.members)} members")
        outs = []
        c = 0 if patches is None else patches.shape[1] // len(self.members)  # each member's channels
        for i, m in enumerate(self.members):
            kw = named if patches is None else {**named, "map_patches": patches[:, i * c : (i + 1) * c]}
            outs.append(getattr(m, method)(*inputs, **kw))
        kept = [o[3] for o in outs if len(o) > 3]
        return self.combine([(o[0], o[1], o[2]) for o in outs]) + ((torch.cat(kept, dim=1),) if kept else ())

    def tile_rows(self, tiles: Tensor) -> Tensor:
        """The kept features of the map's ``tiles`` (contract 13): every member's rows, side by side by channel."""
        return torch.cat([m.tile_rows(tiles) for m in self.members], dim=1)  # type: ignore[operator]
