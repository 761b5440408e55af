r"""Post-inference collision handling (paper §3.4, docs/design.md §5): garment vertices
inside the body move out, each by its own depth plus the offset its
non-colliding neighbours keep, so the corrected patch follows its surroundings
instead of bulging.

With :math:`S(\mathbf{x}) > 0` inside the body (:mod:`swingar_pyg.geometry.signed_distance`) and the
outward direction :math:`\mathbf{n} = -\nabla S / \lVert \nabla S \rVert`, a
colliding vertex :math:`i` moves by

.. math::
    \Delta(\mathbf{x}_i) = \mathbf{n}(\mathbf{x}_i)\,\bigl(S(\mathbf{x}_i) + \delta_i\bigr),
    \qquad
    \delta_i = \frac{\sum_{k} w_{ik} \lvert S(\mathbf{x}_k) \rvert}{\sum_k w_{ik}},
    \quad w_{ik} = \exp\!\Bigl(-\frac{\lVert \mathbf{x}_i - \mathbf{x}_k \rVert^2}
    {2\sigma^2}\Bigr)

over its non-colliding mesh neighbours :math:`k` (:math:`\delta_i = 0` without
any). Where :math:`\delta_i` would carry a vertex into the body again (across a
narrow gap, between the legs), the vertex moves by its own depth alone and lands
on the surface. Moving some vertices can leave others, or create new contacts, so the
step repeats a few times. The baseline (TailorNet's post-process) pushes every
colliding vertex to a fixed offset outside the surface instead.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import torch
import torch.nn.functional as F
from scipy.spatial import cKDTree
from torch import Tensor
from torch_geometric.utils import scatter

from swingar_pyg.geometry.normals import vertex_normals
from swingar_pyg.geometry.signed_distance import BodySurface

SignedDistance = Callable[..., tuple[Tensor, Tensor]]
"""Maps points ``(M, 3)`` to ``S`` ``(M,)`` (positive inside) and ``∇S`` ``(M, 3)``;
given a second argument ``(M,)``, the index of the body each point is worn on."""


@dataclass
class Correction:
    """The corrected vertices, which vertices moved, and the iterations run."""

    vertices: Tensor
    moved: Tensor
    iterations: int


def _outward(gradient: Tensor) -> Tensor:
    # A zero gradient (the centre of a sphere) gives no direction: stay put.
    return -F.normalize(gradient, dim=-1, eps=1e-12)


def resolve_collisions(vertices: Tensor, edge_index: Tensor, signed_distance: SignedDistance,
                       iterations: int = 3, sigma: float | None = None,
                       near: Tensor | None = None, body_index: Tensor | None = None,
                       offset: float = 0.0) -> Correction:
    r"""Moves colliding vertices out of the body (see the module docstring).

    Args:
        vertices: ``(N, 3)`` garment vertices (a Batch of garments is fine:
            neighbours come from ``edge_index`` only).
        edge_index: ``(2, E)`` mesh edges, both directions.
        signed_distance: the body's :math:`S` and :math:`\nabla S`.
        iterations: at most this many correction steps.
        sigma: Gaussian width of the neighbour weights (default: the mean edge
            length).
        near: ``(N,)`` bool, vertices the broad phase found close enough to the
            body to collide; the others are never evaluated nor moved.
        body_index: ``(N,)`` which body each vertex is worn on, when garments
            on several bodies are corrected at once; passed to
            ``signed_distance`` with the points.
        offset: a safety band for an approximate :math:`S` (a network's): a
            vertex counts as colliding from :math:`S > -\text{offset}`, and
            :math:`S` is shifted by ``offset`` in the step, so a vertex lands
            as far out as its free neighbours are, or ``offset`` out without any.
    """
    if iterations < 1:
        raise ValueError(f"iterations must be >= 1, got {iterations}")
    if not torch.isfinite(vertices).all():
        raise ValueError("the garment's vertices are not finite")
    src, dst = edge_index
    if sigma is None:
        lengths = (vertices[src] - vertices[dst]).norm(dim=-1)
        sigma = float(lengths.mean()) if lengths.numel() else 1.0
    candidates = (torch.arange(len(vertices), device=vertices.device) if near is None
                  else near.nonzero().squeeze(-1))
    x = vertices.clone()
    moved = torch.zeros(len(x), dtype=torch.bool, device=x.device)
    run = 0
    for run in range(1, iterations + 1):
        depth = torch.full((len(x),), -torch.inf, dtype=x.dtype, device=x.device)
        gradient = torch.zeros_like(x)
        if len(candidates):
            arguments = (x[candidates],) if body_index is None else \
                (x[candidates], body_index[candidates])
            depth[candidates], gradient[candidates] = signed_distance(*arguments)
        depth = depth + offset
        colliding = depth > 0
        if not colliding.any():
            run -= 1
            break
        free = ~colliding[src] & torch.isfinite(depth[src])
        weight = torch.exp(-(x[dst] - x[src]).square().sum(-1) / (2 * sigma * sigma)) * free
        spread = scatter(weight * depth[src].abs().nan_to_num(posinf=0.0), dst, dim=0,
                         dim_size=len(x), reduce="sum")
        total = scatter(weight, dst, dim=0, dim_size=len(x), reduce="sum")
        delta = torch.where(total > 0, spread / total.clamp_min(1e-30), torch.zeros_like(total))
        outward = _outward(gradient)
        step = outward * (depth + delta).unsqueeze(-1)
        pushed = (colliding & (delta > 0)).nonzero().squeeze(-1)
        if len(pushed):
            arguments = (x[pushed] + step[pushed],) if body_index is None else \
                (x[pushed] + step[pushed], body_index[pushed])
            lands_inside = signed_distance(*arguments)[0] + offset > 0
            overshoot = pushed[lands_inside]
            step[overshoot] = outward[overshoot] * depth[overshoot].unsqueeze(-1)
        x = torch.where(colliding.unsqueeze(-1), x + step, x)
        moved |= colliding
    return Correction(x, moved, run)


def fixed_offset_push(vertices: Tensor, signed_distance: SignedDistance,
                      offset: float = 0.004) -> Correction:
    """The baseline: every colliding vertex moves along the outward normal to
    ``offset`` outside the surface, whatever its neighbours do."""
    depth, gradient = signed_distance(vertices)
    colliding = depth > 0
    step = _outward(gradient) * (depth + offset).unsqueeze(-1)
    return Correction(torch.where(colliding.unsqueeze(-1), vertices + step, vertices),
                      colliding, 1)


def exact_signed_distance(body_vertices: Tensor, body_faces: Tensor) -> SignedDistance:
    """:math:`S` and :math:`\\nabla S` of a posed body mesh, exactly (slow: the
    reference for metrics and for checking the network)."""
    surface = BodySurface(body_vertices.detach().cpu().numpy(), body_faces.cpu().numpy())

    def evaluate(points: Tensor) -> tuple[Tensor, Tensor]:
        s, n = surface.signed_distance(points.detach().cpu().numpy())
        return (torch.as_tensor(s, dtype=points.dtype, device=points.device),
                -torch.as_tensor(n, dtype=points.dtype, device=points.device))

    return evaluate


def nearest_vertex_signed_distance(body_vertices: Tensor, body_faces: Tensor) -> SignedDistance:
    r"""TailorNet's test: :math:`S = (\mathbf{b} - \mathbf{x}) \cdot \mathbf{n}_b` with
    :math:`\mathbf{b}` the body vertex nearest to :math:`\mathbf{x}` and
    :math:`\mathbf{n}_b` its normal, :math:`\nabla S = -\mathbf{n}_b`. Fast (a
    KD-tree), but the nearest vertex's tangent plane is not the surface where
    the surface curves within a vertex spacing (armpits, crotch, fingers)."""
    normals = vertex_normals(body_vertices, body_faces)
    tree = cKDTree(body_vertices.detach().cpu().numpy())

    def evaluate(points: Tensor) -> tuple[Tensor, Tensor]:
        _, index = tree.query(points.detach().cpu().numpy())
        index = torch.as_tensor(index, device=points.device)
        normal = normals[index].to(points)
        return ((body_vertices[index].to(points) - points) * normal).sum(-1), -normal

    return evaluate
