r"""Training losses of the estimator (docs/design.md §4), on frames ``(F, N, 3)`` of a
Batch of garments; positions in metres.

- vertex: :math:`\frac{1}{FN}\sum \lVert \mathbf{x} - \hat{\mathbf{x}} \rVert^2`
- edge length: :math:`\frac{1}{F|E|}\sum (\lVert \mathbf{x}_i - \mathbf{x}_j \rVert -
  \lVert \hat{\mathbf{x}}_i - \hat{\mathbf{x}}_j \rVert)^2`
- bending: :math:`\frac{1}{FN}\sum \lVert L\mathbf{x} - L\hat{\mathbf{x}} \rVert^2` with the
  uniform Laplacian :math:`(L\mathbf{x})_i = \operatorname{mean}_{j \in N(i)} \mathbf{x}_j -
  \mathbf{x}_i` (it vanishes on flat regions, so it measures bending)
- velocity: :math:`\frac{1}{(F-1)N}\sum \lVert \Delta_t \mathbf{x} - \Delta_t \hat{\mathbf{x}}
  \rVert^2` over consecutive frames
- collision (PBNS): :math:`\frac{1}{FN}\sum \max(0,\ \epsilon - (\mathbf{x} - \mathbf{b})
  \cdot \mathbf{n}_b)^2` with :math:`\mathbf{b}, \mathbf{n}_b` the nearest posed body sample
  and its normal
- offset: :math:`\frac{1}{FN}\sum \lVert \mathbf{d} \rVert^2` of a learned displacement
  (blend shapes, detail correction): it keeps two terms from growing large in opposite
  directions, a pair that cancels on the training garments but not on new ones
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor
from torch_geometric.utils import scatter, to_dense_batch


def vertex_loss(pred: Tensor, target: Tensor) -> Tensor:
    return (pred - target).square().sum(-1).mean()


def edge_length_loss(pred: Tensor, target: Tensor, edge_index: Tensor) -> Tensor:
    src, dst = edge_index
    length = (pred[:, src] - pred[:, dst]).norm(dim=-1)
    reference = (target[:, src] - target[:, dst]).norm(dim=-1)
    return (length - reference).square().mean()


def uniform_laplacian(x: Tensor, edge_index: Tensor) -> Tensor:
    """:math:`\\operatorname{mean}_{j \\in N(i)} x_j - x_i` for ``x`` ``(F, N, 3)``;
    zero at isolated vertices."""
    src, dst = edge_index
    mean = scatter(x[:, src], dst, dim=1, dim_size=x.size(1), reduce="mean")
    degree = scatter(torch.ones_like(dst, dtype=x.dtype), dst, dim=0, dim_size=x.size(1))
    return torch.where(degree[None, :, None] > 0, mean - x, torch.zeros_like(x))


def bending_loss(pred: Tensor, target: Tensor, edge_index: Tensor) -> Tensor:
    return (uniform_laplacian(pred, edge_index) -
            uniform_laplacian(target, edge_index)).square().sum(-1).mean()


def offset_loss(offsets: Tensor) -> Tensor:
    return offsets.square().sum(-1).mean()


def velocity_loss(pred: Tensor, target: Tensor) -> Tensor:
    return ((pred[1:] - pred[:-1]) - (target[1:] - target[:-1])).square().sum(-1).mean()


def pose_body_points(points: Tensor, normals: Tensor, skin_indices: Tensor,
                     skin_weights: Tensor, transforms: Tensor) -> tuple[Tensor, Tensor]:
    """Skins rest body samples ``(G, P, 3)`` with per-garment transforms
    ``(G, J, 4, 4)``; returns posed points and unit normals, ``(G, P, 3)`` each."""
    graphs = torch.arange(len(points), device=points.device)[:, None, None]
    blended = (skin_weights[..., None, None] *
               transforms[graphs, skin_indices][..., :3, :]).sum(2)  # (G, P, 3, 4)
    posed = (blended[..., :3] @ points.unsqueeze(-1)).squeeze(-1) + blended[..., 3]
    turned = F.normalize((blended[..., :3] @ normals.unsqueeze(-1)).squeeze(-1), dim=-1)
    return posed, turned


def collision_loss(pred: Tensor, batch: Tensor, body_points: Tensor, body_normals: Tensor,
                   margin: float = 0.004) -> Tensor:
    """PBNS collision penalty; ``pred`` ``(N, 3)`` of one frame, ``batch`` ``(N,)``,
    posed body samples and normals ``(G, P, 3)``."""
    dense, mask = to_dense_batch(pred, batch, batch_size=len(body_points))
    with torch.no_grad():
        nearest = torch.cdist(dense, body_points).argmin(dim=-1)  # (G, Nmax)
    rows = torch.arange(len(body_points), device=pred.device)[:, None]
    depth = margin - ((dense - body_points[rows, nearest]) * body_normals[rows, nearest]).sum(-1)
    return F.relu(depth)[mask].square().mean()
