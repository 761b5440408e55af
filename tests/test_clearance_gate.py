import numpy as np
import pytest
import torch
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from swingar_pyg.models import SwinGarEstimator
from swingar_pyg.models.clearance_gate import ANCHOR_TOLERANCE, anchor_distance, clearance_gate
from tests.windows import SMALL_ESTIMATOR


def grid_mesh(rows: int, columns: int, spacing: float = 0.01, seed: int = 0):
    """A jittered grid's vertices ``(N, 3)`` and its edges ``(2, E)`` (one direction)."""
    generator = torch.Generator().manual_seed(seed)
    u, v = torch.meshgrid(torch.arange(rows), torch.arange(columns), indexing='ij')
    positions = torch.stack([u, v, torch.zeros_like(u)], -1).reshape(-1, 3).double() * spacing
    positions = positions + 0.3 * spacing * torch.rand(positions.shape, generator=generator,
                                                       dtype=torch.float64)
    index = torch.arange(rows * columns).reshape(rows, columns)
    edges = [torch.stack([index[:, :-1].reshape(-1), index[:, 1:].reshape(-1)]),
             torch.stack([index[:-1].reshape(-1), index[1:].reshape(-1)]),
             torch.stack([index[:-1, :-1].reshape(-1), index[1:, 1:].reshape(-1)])]
    return positions, torch.cat(edges, 1)


def dijkstra_to(anchored: torch.Tensor, edges: torch.Tensor, positions: torch.Tensor):
    """The reference: scipy's multi-source Dijkstra on the same weighted graph."""
    n = len(positions)
    lengths = (positions[edges[0]] - positions[edges[1]]).norm(dim=-1).numpy()
    graph = coo_matrix((lengths, (edges[0].numpy(), edges[1].numpy())), shape=(n, n)).tocsr()
    sources = np.flatnonzero(anchored.numpy())
    return torch.as_tensor(dijkstra(graph, directed=False, indices=sources, min_only=True))


def test_anchor_distance_is_the_shortest_path_to_the_cloth_on_the_body():
    positions, edges = grid_mesh(12, 9)
    # a second piece with no anchor, and an isolated vertex
    piece, piece_edges = grid_mesh(3, 3, seed=1)
    positions = torch.cat([positions, piece + 1.0, torch.tensor([[5.0, 5.0, 5.0]]).double()])
    edges = torch.cat([edges, piece_edges + 108], 1)
    anchored = torch.zeros(len(positions), dtype=torch.bool)
    anchored[[0, 50, 77]] = True
    distance = anchor_distance(anchored, edges, positions)
    reference = dijkstra_to(anchored, edges, positions)
    assert torch.allclose(distance, reference, rtol=1e-12)
    assert torch.isinf(distance[108:]).all() and (distance[anchored] == 0).all()
    # either edge direction, and float32 (positions in float32) to its rounding
    assert torch.equal(anchor_distance(anchored, edges.flip(0), positions), distance)
    single = anchor_distance(anchored, edges, positions.float())
    assert single.dtype == torch.float32
    assert torch.allclose(single[:108].double(), reference[:108], rtol=1e-5)
    # half precision in, float32 arithmetic: finite and close where reachable
    half = anchor_distance(anchored, edges, positions.half())
    assert torch.allclose(half[:108].double(), reference[:108], rtol=2e-3, atol=1e-4)
    with pytest.raises(ValueError, match='does not match positions'):
        anchor_distance(anchored[:-1], edges, positions)


@pytest.mark.parametrize('scale', [1e-3, 1e3])
def test_the_gate_is_finite_on_tiny_and_huge_garments(scale):
    positions, edges = grid_mesh(10, 10)
    fit = torch.full((100,), 0.02, dtype=torch.float64)
    fit[:10] = 0.006  # one row on the body
    gate = clearance_gate(fit * scale, 0.006 * scale, 0.02 * scale, 0.05 * scale, edges,
                          positions * scale)
    assert torch.isfinite(gate).all()
    if scale > 1:  # lengths scaled with the scales (the tolerance, in metres, is negligible)
        assert torch.allclose(gate, clearance_gate(fit, 0.006, 0.02, 0.05, edges, positions),
                              rtol=1e-9)
    else:  # the tolerance is in metres: every vertex of a millimetre garment lies on the body
        assert torch.equal(gate, torch.zeros_like(gate))


def test_anchor_distance_on_degenerate_graphs():
    empty = anchor_distance(torch.zeros(0, dtype=torch.bool), torch.zeros(2, 0, dtype=torch.long),
                            torch.zeros(0, 3))
    assert empty.shape == (0,)
    no_edges = anchor_distance(torch.tensor([True, False]), torch.zeros(2, 0, dtype=torch.long),
                               torch.rand(2, 3))
    assert no_edges[0] == 0 and torch.isinf(no_edges[1])
    positions, edges = grid_mesh(6, 6)
    anchored = torch.arange(36) == 0
    reference = anchor_distance(anchored, edges, positions)
    # int32 indices, self loops, duplicate and reversed edges: the same distances
    loops = torch.arange(36).repeat(2, 1)
    messy = torch.cat([edges, edges.flip(0), edges, loops], 1).int()
    assert torch.equal(anchor_distance(anchored, messy, positions), reference)
    # a NaN position ends the relaxation instead of running N rounds: no hang, NaN reported
    broken = positions.clone()
    broken[20] = float('nan')
    assert torch.isnan(anchor_distance(anchored, edges, broken)).any()


def test_the_gate_is_one_factor_per_scale():
    positions, edges = grid_mesh(10, 10)
    fit = torch.linspace(0.0, 0.05, 100, dtype=torch.float64)
    fit[[3, 40]] = 0.006 + ANCHOR_TOLERANCE / 2  # on the body up to float rounding
    room = (fit - 0.006).clamp_min(0)
    clearance_only = clearance_gate(fit, 0.006, 0.02)
    assert torch.allclose(clearance_only.squeeze(-1), 1 - torch.exp(-room / 0.02))
    anchored = fit <= 0.006 + ANCHOR_TOLERANCE
    distance = dijkstra_to(anchored, edges, positions)
    both = clearance_gate(fit, 0.006, 0.02, 0.03, edges, positions).squeeze(-1)
    assert torch.allclose(both, (1 - torch.exp(-room / 0.02)) * (1 - torch.exp(-distance / 0.03)))
    anchor_only = clearance_gate(fit, 0.006, None, 0.03, edges, positions).squeeze(-1)
    assert torch.allclose(anchor_only, 1 - torch.exp(-distance / 0.03))
    assert (anchor_only[anchored] == 0).all() and (anchor_only[~anchored] > 0).all()
    # a garment that touches the body nowhere keeps the clearance factor alone
    loose = fit + 0.01
    assert torch.equal(clearance_gate(loose, 0.006, 0.02, 0.03, edges, positions),
                       clearance_gate(loose, 0.006, 0.02))
    assert clearance_gate(fit, 0.006, None) is None
    with pytest.raises(ValueError, match='needs the garment'):
        clearance_gate(fit, 0.006, 0.02, 0.03)


def test_the_estimator_skins_cloth_held_by_its_neighbours_rigidly(tiny_windows):
    from swingar_pyg.models.estimator import skin_points
    from tests.test_estimator import random_rotations, trained_like

    batch = next(iter(tiny_windows.val_dataloader()))
    transforms = torch.eye(4).repeat(*batch.joint_transforms.shape[:3], 1, 1)
    transforms[..., :3, :3] = random_rotations(transforms[..., 0, 0].numel()).view(
        *transforms.shape[:3], 3, 3)
    batch.joint_transforms = transforms  # every joint its own way: the weights matter
    prior = batch.prior_weights.clamp_min(1e-6)
    rigid = torch.stack([skin_points(batch.rest, prior / prior.sum(-1, keepdim=True),
                                     transforms[:, k], batch.batch) for k in range(3)])
    ungated = trained_like()
    torch.nn.init.normal_(ungated.skinning_head.bias, std=1.0)
    # no vertex lies on the body (fit 5 cm everywhere) but the first of each garment
    batch.fit = torch.full_like(batch.fit, 0.05)
    first = batch.ptr[:-1]
    batch.fit[first] = 0.006
    anchored = trained_like(anchor_scale=0.03, contact_clearance=0.006)
    anchored.load_state_dict(ungated.state_dict())
    gate = anchored.clearance_gate(batch.fit, batch.edge_index, batch.rest).squeeze(-1)
    # per garment of the batch, as one graph on its own: the disjoint batch changes nothing
    for k in range(batch.num_graphs):
        start, end = int(batch.ptr[k]), int(batch.ptr[k + 1])
        alone = anchored.clearance_gate(batch.fit[start:end],
                                        batch[k].edge_index, batch[k].rest).squeeze(-1)
        assert torch.allclose(gate[start:end], alone)
    assert (gate[first] == 0).all() and (gate > 0).sum() == batch.num_nodes - len(first)
    with torch.no_grad():
        held, free = anchored(batch), ungated(batch)
    # rigid where the cloth lies on the body, the learned terms faded in along the cloth:
    # the nearer a vertex, the closer to rigid skinning
    assert torch.allclose(held.vertices[:, first], rigid[:, first], atol=2e-5)
    assert (free.vertices[:, first] - rigid[:, first]).norm(dim=-1).min() > 1e-3
    off_rigid = (held.vertices - rigid).norm(dim=-1).mean(0)
    low, high = gate[gate > 0].quantile(torch.tensor([1 / 3, 2 / 3]))
    near, far = (gate > 0) & (gate < low), gate > high
    assert off_rigid[near].mean() < 0.8 * off_rigid[far].mean()
    for value in (0.0, -1.0, float('inf'), float('nan')):
        with pytest.raises(ValueError, match='anchor_scale must be finite positive'):
            SwinGarEstimator(**{**SMALL_ESTIMATOR, 'anchor_scale': value})
    with pytest.raises(ValueError, match='anchor_scale fades the learned terms'):
        SwinGarEstimator(**{**SMALL_ESTIMATOR, 'anchor_scale': 0.03, 'skinning_prior': False})
