import math

import pytest
import torch
import torch.nn.functional as F
from torch.func import jvp, vjp
from torch_geometric.data import Batch
from torch_geometric.nn import GATConv
from torch_geometric.utils import add_self_loops, to_torch_coo_tensor, to_torch_csc_tensor

from swingar_pyg.nn import FCAConv, attention_edge_index
from tests.graphs import sheet_graph

EDGE_INDEX = torch.tensor([[0, 1, 2, 3, 0, 2, 4, 5, 1], [1, 2, 3, 0, 2, 0, 5, 4, 3]])


def reference_scores(conv: FCAConv, x: torch.Tensor, edge_index: torch.Tensor) -> torch.Tensor:
    """e*_ij straight from the formula in docs/design.md §2, with loops over nodes (float64)."""
    heads, channels = conv.heads, conv.out_channels
    h = (x.double() @ conv.lin.weight.double().t()).view(-1, heads, channels)
    a_src = conv.att_src.double()[0]
    a_dst = conv.att_dst.double()[0]
    loops, _ = add_self_loops(edge_index, num_nodes=x.size(0))
    scores = torch.empty(loops.size(1), heads, dtype=torch.float64)
    for e, (j, i) in enumerate(loops.t().tolist()):
        neighbours = loops[0, loops[1] == i]
        for k in range(heads):
            raw = a_dst[k] @ h[i, k] + a_src[k] @ h[j, k]
            att_norm = torch.cat([a_dst[k], a_src[k]]).norm()
            pair_norm = max(torch.cat([h[i, k], h[n, k]]).norm() for n in neighbours)
            scores[e, k] = conv.alpha * raw / (att_norm * pair_norm)
    return loops, scores


def test_shapes_and_repr():
    x = torch.randn(6, 16)
    conv = FCAConv(16, 8, heads=3)
    assert str(conv) == 'FCAConv(16, 8, heads=3, alpha=2.0)'
    assert conv(x, EDGE_INDEX).shape == (6, 24)
    conv = FCAConv(16, 8, heads=3, concat=False, normalize=False)
    assert str(conv) == 'FCAConv(16, 8, heads=3, normalize=False)'
    assert conv(x, EDGE_INDEX).shape == (6, 8)


def test_negative_alpha_is_rejected():
    with pytest.raises(ValueError, match="'alpha' must be non-negative"):
        FCAConv(4, 4, alpha=-1.0)


def test_deterministic_and_reset_parameters():
    x = torch.randn(6, 16)
    conv = FCAConv(16, 8, heads=2)
    out = conv(x, EDGE_INDEX)
    assert torch.equal(out, conv(x, EDGE_INDEX))
    before = conv.lin.weight.clone()
    conv.reset_parameters()
    assert not torch.equal(before, conv.lin.weight)


def test_attention_matches_the_formula():
    x = torch.randn(6, 5)
    conv = FCAConv(5, 4, heads=2, alpha=1.5).double()
    out, (loops, weights) = conv(x.double(), EDGE_INDEX, return_attention_weights=True)
    ref_loops, ref_scores = reference_scores(conv, x, EDGE_INDEX)
    assert torch.equal(loops, ref_loops)
    logits = F.leaky_relu(ref_scores, 0.2)
    expected = torch.empty_like(logits)
    for i in range(x.size(0)):
        incoming = ref_loops[1] == i
        expected[incoming] = torch.softmax(logits[incoming], dim=0)
    assert torch.allclose(weights, expected, atol=1e-12)


@pytest.mark.parametrize('kind', ['random', 'huge', 'tiny', 'all_equal', 'zero'])
def test_score_bound_and_attention_bounds(kind):
    torch.manual_seed(3)
    x = {'random': torch.randn(6, 5), 'huge': 1e6 * torch.randn(6, 5),
         'tiny': 1e-6 * torch.randn(6, 5), 'all_equal': torch.ones(6, 5),
         'zero': torch.zeros(6, 5)}[kind]
    alpha, slope = 2.0, 0.2
    conv = FCAConv(5, 4, heads=3, alpha=alpha, negative_slope=slope).double()
    _, scores = reference_scores(conv, x, EDGE_INDEX) if kind != 'zero' else (None, torch.zeros(1))
    assert scores.abs().max() <= alpha * (1 + 1e-12)

    out, (loops, weights) = conv(x.double(), EDGE_INDEX, return_attention_weights=True)
    assert torch.isfinite(out).all() and torch.isfinite(weights).all()
    degree = torch.bincount(loops[1], minlength=6).double()[loops[1]].unsqueeze(-1)
    spread = math.exp((1 + slope) * alpha)
    assert (weights * degree >= 1 / spread - 1e-12).all()
    assert (weights * degree <= spread + 1e-12).all()


def test_attention_sums_to_one_per_node():
    x = torch.randn(6, 5)
    _, (loops, weights) = FCAConv(5, 4, heads=2)(x, EDGE_INDEX, return_attention_weights=True)
    assert weights.shape == (loops.size(1), 2)
    assert ((weights >= 0) & (weights <= 1)).all()
    totals = torch.zeros(6, 2).index_add_(0, loops[1], weights)
    assert torch.allclose(totals, torch.ones(6, 2), atol=1e-6)


@pytest.mark.parametrize('scale', [1e-3, 1e3])
def test_invariant_to_input_scale(scale):
    x = torch.randn(6, 5, dtype=torch.float64)
    conv = FCAConv(5, 4, heads=2, bias=False).double()
    out, (_, weights) = conv(x, EDGE_INDEX, return_attention_weights=True)
    scaled_out, (_, scaled_weights) = conv(scale * x, EDGE_INDEX, return_attention_weights=True)
    assert torch.allclose(weights, scaled_weights, rtol=1e-9, atol=1e-12)
    assert torch.allclose(scaled_out, scale * out, rtol=1e-9, atol=1e-12 * scale)


def test_alpha_zero_is_mean_aggregation():
    x = torch.randn(6, 5)
    conv = FCAConv(5, 4, heads=2, alpha=0.0)
    adjacency = torch.eye(6)
    adjacency[EDGE_INDEX[1], EDGE_INDEX[0]] = 1.0
    mean = (adjacency / adjacency.sum(1, keepdim=True)) @ conv.lin(x)
    assert torch.allclose(conv(x, EDGE_INDEX), mean + conv.bias, atol=1e-6)


def test_without_normalization_it_is_gatconv():
    x = torch.randn(6, 16)
    gat = GATConv(16, 8, heads=3)
    torch.nn.init.normal_(gat.bias)
    conv = FCAConv(16, 8, heads=3, normalize=False)
    conv.load_state_dict(gat.state_dict())
    assert torch.allclose(conv(x, EDGE_INDEX), gat(x, EDGE_INDEX), atol=1e-6)


def test_dense_and_sparse_adjacency_agree():
    x = torch.randn(6, 16)
    conv = FCAConv(16, 8, heads=2)
    out, (loops, weights) = conv(x, EDGE_INDEX, return_attention_weights=True)
    for adj in (to_torch_csc_tensor(EDGE_INDEX, size=(6, 6)).t(),
                to_torch_coo_tensor(EDGE_INDEX.flip(0), size=(6, 6))):
        sparse_out, (sparse_adj, sparse_weights) = conv(x, adj, return_attention_weights=True)
        assert torch.allclose(out, sparse_out, atol=1e-6)
        assert sparse_adj.layout in (torch.sparse_coo, torch.sparse_csr, torch.sparse_csc)
        dense = torch.zeros(6, 6, 2)
        dense[loops[1], loops[0]] = weights
        assert torch.allclose(sparse_adj.to_dense(), dense, atol=1e-6)


def test_prepared_attention_graph_agrees_and_batches():
    graphs = [sheet_graph(6, 7, 8, jitter=0.3), sheet_graph(4, 9, 8, seed=3)]
    conv = FCAConv(8, 4, heads=2)
    prepared_conv = FCAConv(8, 4, heads=2, add_self_loops=False)
    prepared_conv.load_state_dict(conv.state_dict())
    for graph in graphs:
        expected = conv(graph.x, graph.edge_index)
        graph.edge_index = attention_edge_index(graph.edge_index, graph.num_nodes)
        assert graph.edge_index.is_sorted_by_col
        assert torch.allclose(prepared_conv(graph.x, graph.edge_index), expected, atol=1e-6)
    batch = Batch.from_data_list(graphs)
    assert batch.edge_index.is_sorted_by_col
    out = prepared_conv(batch.x, batch.edge_index)
    assert torch.allclose(out[batch.ptr[1]:], prepared_conv(graphs[1].x, graphs[1].edge_index),
                          atol=1e-6)


@pytest.mark.parametrize('concat', [True, False])
def test_fused_inference_aggregation_equals_message_passing(concat):
    graphs = [sheet_graph(6, 7, 8, jitter=0.3), sheet_graph(4, 9, 8, seed=3)]
    for graph in graphs:
        graph.edge_index = attention_edge_index(graph.edge_index, graph.num_nodes)
    batch = Batch.from_data_list(graphs)
    fused = FCAConv(8, 5, heads=3, concat=concat, add_self_loops=False).double()
    scattered = FCAConv(8, 5, heads=3, concat=concat, add_self_loops=False,
                        fused_aggregation=False).double()
    scattered.load_state_dict(fused.state_dict())
    x = batch.x.double()
    with torch.no_grad():
        expected = scattered(x, batch.edge_index)
        assert torch.allclose(fused(x, batch.edge_index), expected, rtol=1e-12, atol=1e-12)
        alone = fused(graphs[1].x.double(), graphs[1].edge_index)
        assert torch.allclose(alone, expected[batch.ptr[1]:], rtol=1e-12, atol=1e-12)
    # With gradients the layer runs message passing, so autograd sees the same graph as before.
    x.requires_grad_(True)
    fused(x, batch.edge_index).square().sum().backward()
    fused_grad = x.grad.clone()
    x.grad = None
    scattered(x, batch.edge_index).square().sum().backward()
    assert torch.allclose(fused_grad, x.grad, rtol=1e-12, atol=1e-12)


def test_large_alpha_falls_back_to_the_shifted_softmax():
    x = torch.randn(6, 5, dtype=torch.float64)
    conv = FCAConv(5, 4, heads=2, alpha=80.0).double()
    _, (loops, weights) = conv(x, EDGE_INDEX, return_attention_weights=True)
    _, ref_scores = reference_scores(conv, x, EDGE_INDEX)
    logits = F.leaky_relu(ref_scores, 0.2)
    for i in range(6):
        incoming = loops[1] == i
        assert torch.allclose(weights[incoming], torch.softmax(logits[incoming], 0))


def test_bipartite():
    x_src, x_dst = torch.randn(6, 16), torch.randn(4, 8)
    edge_index = torch.tensor([[1, 2, 3, 4, 5, 0], [0, 0, 1, 2, 3, 3]])
    conv = FCAConv((16, 8), 4, heads=2)
    assert conv((x_src, x_dst), edge_index, size=(6, 4)).shape == (4, 8)
    out, (loops, weights) = conv((x_src, x_dst), edge_index, size=(6, 4),
                                 return_attention_weights=True)
    assert loops.size(1) == edge_index.size(1) + 4  # self-loops on the 4 shared nodes
    no_loops = FCAConv((16, 8), 4, heads=2, add_self_loops=False)
    out, (loops, weights) = no_loops((x_src, None), edge_index, size=(6, 4),
                                     return_attention_weights=True)
    assert out.shape == (4, 8) and torch.equal(loops, edge_index)
    totals = torch.zeros(4, 2).index_add_(0, loops[1], weights)
    assert torch.allclose(totals, torch.ones(4, 2), atol=1e-6)


def test_garment_in_a_batch_equals_standalone():
    garments = [sheet_graph(5, 7, 6, seed=0), sheet_graph(9, 4, 6, jitter=0.3, seed=1),
                sheet_graph(3, 3, 6, seed=2)]
    # One garment at a huge scale must not change the others' normalisation.
    garments[1].x = garments[1].x * 1e4
    conv = FCAConv(6, 4, heads=2)
    batch = Batch.from_data_list(garments)
    batched = conv(batch.x, batch.edge_index)
    for index, garment in enumerate(garments):
        alone = conv(garment.x, garment.edge_index)
        part = batched[batch.ptr[index]:batch.ptr[index + 1]]
        assert torch.allclose(part, alone, rtol=1e-6, atol=1e-6 * alone.abs().max().item())


def test_gradcheck_float64():
    x = torch.randn(6, 3, dtype=torch.float64, requires_grad=True)
    conv = FCAConv(3, 2, heads=2).double()
    assert torch.autograd.gradcheck(lambda x: conv(x, EDGE_INDEX), (x,))
    params = dict(conv.named_parameters())

    def by_parameters(att_src, weight):
        return torch.func.functional_call(
            conv, {**params, 'att_src': att_src, 'lin.weight': weight}, (x.detach(), EDGE_INDEX))

    assert torch.autograd.gradcheck(
        by_parameters, (params['att_src'].detach().requires_grad_(),
                        params['lin.weight'].detach().requires_grad_()))


def test_gradients_finite_on_zero_input():
    x = torch.zeros(6, 5, requires_grad=True)
    conv = FCAConv(5, 4)
    conv(x, EDGE_INDEX).sum().backward()
    assert torch.isfinite(x.grad).all()
    assert all(torch.isfinite(p.grad).all() for p in conv.parameters())


def _lipschitz_estimate(function, x, iterations=60):
    """Largest singular value of the Jacobian at x, by power iteration on J^T J."""
    v = torch.randn_like(x)
    v = v / v.norm()
    _, pullback = vjp(function, x)
    for _ in range(iterations):
        _, jv = jvp(function, (x,), (v,))
        (v,) = pullback(jv)
        v = v / v.norm()
    _, jv = jvp(function, (x,), (v,))
    return jv.norm().item()


def test_lipschitz_bounded_as_input_grows_while_gat_is_not():
    graph = sheet_graph(5, 5, 6)
    fca = FCAConv(6, 6, bias=False).double()
    gat = GATConv(6, 6, bias=False).double()
    gat.load_state_dict(fca.state_dict())
    # Where GAT's scores tie across a neighbourhood its Jacobian grows with the
    # input (Dasoulas et al., 2021): remove the input's components that the
    # scores see, so every score is zero at any scale.
    score_rows = torch.stack([fca.lin.weight.t() @ fca.att_src.view(-1),
                              fca.lin.weight.t() @ fca.att_dst.view(-1)], dim=1).detach()
    basis, _ = torch.linalg.qr(score_rows)
    x = graph.x.double()
    x = x - (x @ basis) @ basis.t()

    def estimate(conv, scale):
        return _lipschitz_estimate(lambda y: conv(y, graph.edge_index), scale * x)

    fca_small, fca_large = estimate(fca, 1.0), estimate(fca, 1e3)
    gat_small, gat_large = estimate(gat, 1.0), estimate(gat, 1e3)
    assert fca_large < 1.05 * fca_small
    assert gat_large > 100 * gat_small


@pytest.mark.parametrize('dtype', [torch.float32, torch.float64, torch.bfloat16, torch.float16])
def test_dtypes(dtype):
    graph = sheet_graph(6, 6, 8)
    conv = FCAConv(8, 4, heads=2)
    reference = conv.double()(graph.x.double(), graph.edge_index)
    out = conv.to(dtype)(graph.x.to(dtype), graph.edge_index)
    assert out.dtype == dtype and torch.isfinite(out).all()
    tolerance = {torch.float32: 1e-5, torch.float64: 1e-12,
                 torch.bfloat16: 5e-2, torch.float16: 1e-2}[dtype]
    assert torch.allclose(out.double(), reference, atol=tolerance * reference.abs().max().item())


def test_half_precision_with_large_features_stays_finite():
    graph = sheet_graph(6, 6, 8)
    conv = FCAConv(8, 4).half()
    out = conv(300 * graph.x.half(), graph.edge_index)  # ||h||^2 overflows float16
    assert torch.isfinite(out).all()


def test_isolated_nodes_keep_their_own_features():
    x = torch.randn(8, 5)
    conv = FCAConv(5, 4, heads=2)
    out = conv(x, EDGE_INDEX)  # nodes 6 and 7 have no edges
    assert torch.allclose(out[6:], conv.lin(x[6:]) + conv.bias, atol=1e-6)


@pytest.mark.parametrize('backend', [
    'aot_eager',  # traces forward and backward graphs: proves there is no graph break
    pytest.param('inductor', marks=pytest.mark.slow),  # generates and compiles C++ (~20 s)
])
def test_compiles_without_graph_breaks(backend):
    graph = sheet_graph(6, 6, 8)
    edge_index, _ = add_self_loops(graph.edge_index, num_nodes=graph.num_nodes)
    conv = FCAConv(8, 4, heads=2, add_self_loops=False)
    x = graph.x.requires_grad_()
    expected = conv(x, edge_index)
    (expected_grad,) = torch.autograd.grad(expected.square().sum(), x)
    compiled = torch.compile(conv, fullgraph=True, backend=backend)
    out = compiled(x, edge_index)
    (grad,) = torch.autograd.grad(out.square().sum(), x)
    assert torch.allclose(out, expected, atol=1e-5)
    assert torch.allclose(grad, expected_grad, atol=1e-4)
