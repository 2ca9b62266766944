"""The graph attention of DGAN (paper §3.3): a layer over the attention-zone graph's edge list for training, and the
same layer over the contract's padded neighbour lists for export, in one group or in two by degree."""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import Tensor, nn


class GATLayer(nn.Module):
    """Multi-head graph attention over directed edges ``[receiver, sender]`` with edge features."""

    def __init__(self, dim: int, heads: int, edge_dim: int) -> None:
        super().__init__()
        self.heads, self.dh = heads, dim // heads
        self.w = nn.Linear(dim, dim, bias=False)
        self.we = nn.Sequential(nn.Linear(edge_dim, dim), nn.ReLU(), nn.Linear(dim, dim))
        self.a_recv = nn.Parameter(torch.randn(heads, self.dh) * 0.1)
        self.a_send = nn.Parameter(torch.randn(heads, self.dh) * 0.1)
        self.out = nn.Linear(dim, dim)
        self.norm = nn.LayerNorm(dim)

    def forward(self, h: Tensor, edge_index: Tensor, edge_features: Tensor) -> Tensor:
        n = h.shape[0]
        recv, send = edge_index[:, 0], edge_index[:, 1]
        wh = self.w(h).view(n, self.heads, self.dh)
        msg = wh[send] + self.we(edge_features).view(-1, self.heads, self.dh)
        score = nn.functional.leaky_relu((wh[recv] * self.a_recv).sum(-1) + (msg * self.a_send).sum(-1), 0.2)
        weight = torch.exp(torch.clamp(score, -20.0, 20.0))  # (E, H)
        # scatter_add, not index_add: the ONNX export of index_add mishandles repeated receivers.
        r2 = recv.unsqueeze(-1).expand(-1, self.heads)
        denom = torch.zeros(n, self.heads, dtype=h.dtype, device=h.device).scatter_add(0, r2, weight)
        alpha = weight / (torch.gather(denom, 0, r2) + 1e-9)
        r3 = recv.view(-1, 1, 1).expand(-1, self.heads, self.dh)
        agg = torch.zeros(n, self.heads, self.dh, dtype=h.dtype, device=h.device)
        agg = agg.scatter_add(0, r3, alpha.unsqueeze(-1) * msg)
        out: Tensor = self.norm(h + nn.functional.elu(self.out(agg.reshape(n, -1))))
        return out

    def forward_padded(self, h: Tensor, groups: NeighborGroups) -> Tensor:
        """The same attention over padded senders, in the groups of :func:`neighbor_groups`: every agent over the
        narrow ``index (N, t)`` (its first t senders), then the receivers wider than t over the full lists, whose
        results replace theirs. ``features (·, ·, 7)`` are the edge features and a column of ones
        (:meth:`DGAN.forward_padded`); ``bias (·, 1, ·)`` is 0 for a real sender and -10⁴ for padding
        (:func:`padding_bias`).

        Arranged for ONNX Runtime, equal in arithmetic (every agent hears at least itself, so each softmax row has a
        real sender; the edge-list form's 1e-9 in the denominator is the only difference):
        - scores in ``(H, N, D)``, normalised by one Softmax over the senders, then the weights in ``(N, H, D)``;
          both layouts reached without a batched ``(N, D, H) -> (N, H, D)`` Transpose, which ONNX Runtime 1.23 runs
          8-15 times slower on two threads than on one for these shapes (docs/speed.md);
        - receiver and sender scores from one matrix product with W folded into a_recv and a_send;
        - the edge MLP's first layer with its bias as the last row of one product against the features' column of
          ones (no pass of its own over the ``(N, D, dim)`` result: the same sums, the bias their last term);
        - the edge MLP's second linear layer W2 applied after the sum over senders (Σ α (W2 e + b2) = W2 (Σ α e) +
          b2, as Σ α = 1), each head's own block of W2 to its own sum, as one product batched over the heads (a
          quarter of the operations of one product with their block-diagonal, which multiplies its zeros: 0.20
          MFLOP an agent of two layers), and its part of the score as the hidden edge vector times W2ᵀ a_send;
        - the messages of the senders' nodes as one batched product α (N, H, D) @ (N, D, dim), of which each head
          keeps its own dh columns.
        The weights-only products are constants that the exporter folds.
        """
        lin2 = self.we[2]
        assert isinstance(lin2, nn.Linear)
        w_t = self.w.weight.t()  # (dim, dim)
        w_heads = w_t.reshape(-1, self.heads, self.dh)
        a_both = torch.cat([(w_heads * self.a_recv).sum(-1), (w_heads * self.a_send).sum(-1)], dim=1)  # (dim, 2H)
        wh = h @ w_t  # (N, dim)
        s = h @ a_both  # (N, 2H)
        agg = self._aggregate(s[:, : self.heads], wh, s[:, self.heads :], *groups.narrow)
        if groups.receivers is not None and groups.wide is not None:
            wide = groups.receivers
            agg = agg.index_put((wide,), self._aggregate(s[wide, : self.heads], wh, s[:, self.heads :], *groups.wide))
        out: Tensor = self.norm(h + nn.functional.elu(self.out(agg + lin2.bias)))
        return out

    def _aggregate(
        self, recv: Tensor, wh: Tensor, send: Tensor, index: Tensor, bias: Tensor, features: Tensor
    ) -> Tensor:
        """The messages to receivers whose scores are ``recv (n, H)``, from the senders ``index (n, d)`` whose rows
        of ``wh (N, dim)`` and scores ``send (N, H)`` they gather: ``(n, dim)``, without the edge MLP's last bias."""
        n, d = index.shape[0], index.shape[1]
        heads, dh = self.heads, self.dh
        lin1, lin2 = self.we[0], self.we[2]
        assert isinstance(lin1, nn.Linear)
        assert isinstance(lin2, nn.Linear)
        w2 = lin2.weight.view(heads, dh, -1)  # (H, dh, dim)
        v = (w2 * self.a_send.unsqueeze(-1)).sum(1).t()  # (dim, H)
        c = (lin2.bias.view(heads, dh) * self.a_send).sum(-1)  # (H,)
        eye = torch.eye(heads, dtype=wh.dtype, device=wh.device)
        own = eye.repeat_interleave(dh, dim=1)  # (H, dim): head k keeps its own dh columns
        hidden = torch.relu(features @ torch.cat([lin1.weight.t(), lin1.bias.unsqueeze(0)]))  # (n, d, dim)
        # (n, d, H) turned as the 2-D (n·d, H), and the weights back to (n, H, d) by moving the outer axis: two
        # Transposes that run on two threads as fast as on one.
        scores = (send[index] + hidden @ v).reshape(-1, heads).t().reshape(heads, n, d)  # (H, n, d)
        score = scores + (recv + c).t().unsqueeze(-1)
        score = torch.clamp(nn.functional.leaky_relu(score, 0.2), -20.0, 20.0) + bias.reshape(1, n, d)
        alpha = torch.softmax(score, dim=-1).transpose(0, 1)  # (n, H, d)
        from_nodes = ((alpha @ wh[index]) * own).sum(1)  # (n, dim)
        # Each head's sum of hidden edge vectors (H, n, dim) times its own W2ᵀ (H, dim, dh), back to (n, H·dh): the
        # outer axis moved twice, which runs on two threads as fast as on one.
        from_edges = ((alpha @ hidden).transpose(0, 1) @ w2.transpose(1, 2)).transpose(0, 1).reshape(n, -1)
        return from_nodes + from_edges


class NeighborGroups(NamedTuple):
    """The padded neighbour lists, in one group or in two (:func:`neighbor_groups`): ``narrow`` = (index, bias,
    features) of every agent's first t senders (all D in one group); ``wide`` the same, full width, of the agents at
    ``receivers`` (None in one group)."""

    narrow: tuple[Tensor, Tensor, Tensor]
    receivers: Tensor | None = None
    wide: tuple[Tensor, Tensor, Tensor] | None = None


def neighbor_groups(index: Tensor, mask: Tensor, features: Tensor) -> NeighborGroups:
    """The contract's padded neighbours ``index (N, D)``, ``mask (N, D)``, ``features (N, D, F)`` in two groups,
    inside the network (the engine's inputs are unchanged): every agent with its first t senders, and the agents with
    more than t senders (and the first of the largest degree, so that the group is never empty) with all D. t is the
    width that costs the fewest padded slots, N·t + (agents wider than t)·D: the per-slot work of the attention (the
    edge MLP, the scores, the messages) then follows the senders that exist rather than N times the frame's largest
    degree (`hdmap`'s frames fill 10-17% of their padded slots). A real sender always lies in the first `degree`
    slots, and padding adds nothing, so every agent's result is that of its full list."""
    n, d = index.shape[0], index.shape[1]
    degree = mask.sum(1)  # (N,)
    widths = torch.arange(1, d + 1, device=index.device).to(degree.dtype)  # (D,)
    wider = (degree.unsqueeze(0) > widths.unsqueeze(1)).to(degree.dtype).sum(1)  # (D,): agents wider than each
    t = torch.argmin(widths * n + wider * d)  # the first cheapest width, less one
    columns = torch.arange(d, device=index.device)[widths <= widths[t]]  # the first t + 1 slots
    bias = padding_bias(mask)
    narrow = (index.index_select(1, columns), bias.index_select(2, columns), features.index_select(1, columns))
    receivers = torch.cat([torch.nonzero(degree > widths[t]).reshape(-1), degree.argmax().reshape(1)])
    return NeighborGroups(narrow, receivers, (index[receivers], bias[receivers], features[receivers]))


def padding_bias(mask: Tensor) -> Tensor:
    """``(N, D)`` sender mask → the ``(N, 1, D)`` additive score bias of :meth:`GATLayer.forward_padded`."""
    return ((mask - 1.0) * 1e4).unsqueeze(1)
