r"""The clearance gate: where an estimator's learned terms apply to a garment.

Rigid skinning is nearly the truth for cloth lying on the body, and for cloth held
by cloth that does: a sport top's hem 1 cm off the belly cannot swing, its
neighbours lie on the skin. With a contact clearance :math:`c_0`, vertex
:math:`i` of rest clearance :math:`c_i` (the garment's ``fit``) gets

.. math::
    g_i = \left(1 - e^{-\max(c_i - c_0,\, 0) / d_0}\right)
          \left(1 - e^{-a_i / l_0}\right),

where :math:`a_i` is the length of the shortest path along the mesh's edges from
:math:`i` to a vertex lying on the body (:math:`c_j \le c_0`, to within
:data:`ANCHOR_TOLERANCE`), :math:`\infty` when none is reachable. Either factor
is left out (is one) without its scale: the clearance scale :math:`d_0` fades the
terms in with room from the body, the anchor scale :math:`l_0` with cloth length
from where the garment touches it. Only cloth lying on the body is skinned
rigidly; cloth held by it is faded towards rigid, the more the nearer. A garment
that touches the body nowhere keeps the clearance factor alone: the anchor set is
a threshold, so cloth dressed a fraction of a millimetre beyond :math:`c_0` holds
nothing.
"""

from __future__ import annotations

import torch
from torch import Tensor

#: Rest clearances within this of the contact clearance count as lying on the
#: body (metres): dressed cloth (:func:`~swingar_pyg.world.garment.garment_on_body`)
#: measures 0.2-10 micrometres beyond the contact clearance it was moved out to.
ANCHOR_TOLERANCE = 1e-4


@torch.compiler.disable
def anchor_distance(anchored: Tensor, edge_index: Tensor, positions: Tensor) -> Tensor:
    r"""The length ``(N,)`` of the shortest path along ``edge_index`` (either
    direction) from each vertex to an ``anchored`` one (``(N,)`` bool), with edge
    lengths from ``positions`` ``(N, 3)``; ``inf`` where none is reachable.

    Bellman-Ford relaxation, :math:`a_j \leftarrow \min(a_j, \min_{(i,j)} a_i +
    \lVert \mathbf{x}_i - \mathbf{x}_j \rVert)`, until no distance shrinks: one
    round more than the longest shortest path has edges, each one scatter over the
    edges (device-agnostic, float32 at least). It runs once per garment (a stream
    computes its gate when it starts), outside compiled code."""
    if anchored.shape != positions.shape[:1]:
        raise ValueError(f"anchored {tuple(anchored.shape)} does not match positions "
                         f"{tuple(positions.shape)}")
    positions = positions.to(torch.promote_types(positions.dtype, torch.float32))
    source, target = torch.cat([edge_index, edge_index.flip(0)], dim=1).long()
    length = (positions[source] - positions[target]).norm(dim=-1)
    distance = torch.full_like(positions[:, 0], float("inf")).masked_fill(anchored, 0.0)
    for _ in range(len(distance)):
        relaxed = distance.scatter_reduce(0, target, distance[source] + length, "amin")
        if not (relaxed < distance).any():  # NaN compares false: a NaN length ends it too
            break
        distance = relaxed
    return distance


def clearance_gate(fit: Tensor, contact_clearance: float, clearance_scale: float | None,
                   anchor_scale: float | None = None, edge_index: Tensor | None = None,
                   positions: Tensor | None = None) -> Tensor | None:
    """:math:`g` ``(N, 1)`` of the rest clearances ``fit`` ``(N,)``, or ``None``
    without either scale. The anchor factor needs the garment's ``edge_index``
    and rest ``positions``."""
    if clearance_scale is None and anchor_scale is None:
        return None
    gate = torch.ones_like(fit)
    if clearance_scale is not None:
        gate = -torch.expm1(-(fit - contact_clearance).clamp_min(0.0) / clearance_scale)
    if anchor_scale is not None:
        if edge_index is None or positions is None:
            raise ValueError("the anchor factor of the clearance gate needs the garment's "
                             "edge_index and rest positions")
        anchored = fit <= contact_clearance + ANCHOR_TOLERANCE
        distance = anchor_distance(anchored, edge_index, positions).to(fit.dtype)
        gate = gate * -torch.expm1(-distance / anchor_scale)
    return gate.unsqueeze(-1)
