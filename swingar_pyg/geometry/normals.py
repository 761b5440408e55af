"""Area-weighted vertex normals, batched and differentiable."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor


def vertex_normals(vertices: Tensor, faces: Tensor) -> Tensor:
    r"""Area-weighted unit vertex normals.

    .. math::
        \mathbf{n}_i = \frac{\sum_{f \ni i} (\mathbf{v}_{f,1} - \mathbf{v}_{f,0})
        \times (\mathbf{v}_{f,2} - \mathbf{v}_{f,0})}{\left\| \cdot \right\|},

    the cross product being twice the face area times its unit normal. Vertices
    are centred and divided by their largest coordinate first: normals do not
    depend on scale, and this keeps the cross products finite for coordinates
    of any magnitude (1e-20 to 1e20) and in half precision. Vertices with no
    incident face of positive area get the zero vector.

    Args:
        vertices: ``(..., N, 3)`` positions (any leading batch dimensions).
        faces: ``(F, 3)`` long vertex indices.

    Returns:
        ``(..., N, 3)`` normals in the dtype of ``vertices``.
    """
    compute_dtype = torch.promote_types(vertices.dtype, torch.float32)
    v = vertices.to(compute_dtype)
    v = v - v.mean(dim=-2, keepdim=True)
    scale = v.abs().amax(dim=(-2, -1), keepdim=True)
    v = v / torch.where(scale > 0, scale, torch.ones_like(scale))
    a, b, c = v[..., faces[:, 0], :], v[..., faces[:, 1], :], v[..., faces[:, 2], :]
    face_normals = torch.cross(b - a, c - a, dim=-1)
    normals = torch.zeros_like(v)
    for corner in range(3):
        normals.index_add_(-2, faces[:, corner], face_normals)
    return F.normalize(normals, dim=-1, eps=1e-30).to(vertices.dtype)
