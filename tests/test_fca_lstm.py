import pytest
import torch
from torch_geometric.data import Batch
from torch_geometric.utils import add_self_loops

from swingar_pyg.nn import FCALSTM, FCAConv
from tests.graphs import sheet_graph


def test_shapes_and_repr():
    graph = sheet_graph(4, 5, 3)
    lstm = FCALSTM(3, 8)
    assert str(lstm) == 'FCALSTM(3, 8, alpha=2.0)'
    steps = torch.randn(3, graph.num_nodes, 3)
    outputs, (h, c) = lstm(steps, graph.edge_index)
    assert outputs.shape == (3, graph.num_nodes, 8)
    assert h.shape == c.shape == (graph.num_nodes, 8)
    assert torch.equal(outputs[-1], h)


def test_matches_the_equations_step_by_step():
    """Independent reference: eq. 6 written out with four separate FCAConv maps
    per path, built from the corresponding head of the fused layers."""
    graph = sheet_graph(3, 4, 3)
    hidden = 5
    lstm = FCALSTM(3, hidden).double()
    with torch.no_grad():
        lstm.peephole.normal_()
    edge_index, _ = add_self_loops(graph.edge_index, num_nodes=graph.num_nodes)

    def head_map(fused, gate, in_channels):
        conv = FCAConv(in_channels, hidden, add_self_loops=False,
                       bias=fused.bias is not None).double()
        rows = slice(gate * hidden, (gate + 1) * hidden)
        with torch.no_grad():
            conv.lin.weight.copy_(fused.lin.weight[rows])
            conv.att_src.copy_(fused.att_src[:, gate:gate + 1])
            conv.att_dst.copy_(fused.att_dst[:, gate:gate + 1])
            if conv.bias is not None:
                conv.bias.copy_(fused.bias[rows])
        return conv

    x_maps = [head_map(lstm.input_maps, g, 3) for g in range(4)]
    h_maps = [head_map(lstm.state_maps, g, hidden) for g in range(4)]
    w_i, w_f, w_o = lstm.peephole
    steps = torch.randn(4, graph.num_nodes, 3, dtype=torch.float64)
    h = c = torch.zeros(graph.num_nodes, hidden, dtype=torch.float64)
    for x in steps:
        pre = [x_maps[g](x, edge_index) + h_maps[g](h, edge_index) for g in range(4)]
        i = torch.sigmoid(pre[0] + w_i * c)
        f = torch.sigmoid(pre[1] + w_f * c)
        c = f * c + i * torch.tanh(pre[2])
        o = torch.sigmoid(pre[3] + w_o * c)
        h = o * torch.tanh(c)
    _, (h_lstm, c_lstm) = lstm(steps, graph.edge_index)
    assert torch.allclose(h_lstm, h, atol=1e-12) and torch.allclose(c_lstm, c, atol=1e-12)


def test_sequence_of_tensors_and_initial_state():
    graph = sheet_graph(4, 4, 3)
    lstm = FCALSTM(3, 6)
    steps = torch.randn(5, graph.num_nodes, 3)
    outputs, state = lstm(steps, graph.edge_index)
    assert torch.equal(lstm(list(steps), graph.edge_index)[0], outputs)
    # Running in two chunks with the state carried over equals one run.
    first, mid_state = lstm(steps[:2], graph.edge_index)
    second, end_state = lstm(steps[2:], graph.edge_index, mid_state)
    assert torch.allclose(torch.cat([first, second]), outputs, atol=1e-6)
    assert torch.allclose(end_state[1], state[1], atol=1e-6)



def test_cached_input_terms_give_the_same_windows():
    """A stream computes each frame's input terms once and reruns only the
    recurrence over a sliding window: that equals running every window anew."""
    graph = sheet_graph(4, 5, 3)
    lstm = FCALSTM(3, 6, add_self_loops=False).double()
    edge_index, _ = add_self_loops(graph.edge_index, num_nodes=graph.num_nodes)
    frames = torch.randn(6, graph.num_nodes, 3, dtype=torch.float64)
    terms = [lstm.input_terms(x, edge_index) for x in frames]
    for end in range(3, 7):
        state = None
        for input_terms in terms[end - 3:end]:
            state = lstm.step_from_input_terms(input_terms, edge_index, state)
        _, expected = lstm(frames[end - 3:end], edge_index)
        assert torch.allclose(state[0], expected[0], atol=1e-12)
        assert torch.allclose(state[1], expected[1], atol=1e-12)

def test_bad_input_shape_raises():
    lstm = FCALSTM(3, 4)
    with pytest.raises(ValueError, match=r"shape \(T, N, F\)"):
        lstm(torch.randn(5, 3), torch.zeros(2, 0, dtype=torch.long))


def test_batch_equals_each_graph_alone():
    graphs = [sheet_graph(3, 5, 3, seed=0), sheet_graph(6, 4, 3, jitter=0.2, seed=1)]
    for graph in graphs:
        graph.steps = torch.randn(graph.num_nodes, 4, 3)  # nodes first, for batching
    batch = Batch.from_data_list(graphs)
    lstm = FCALSTM(3, 6)
    outputs, _ = lstm(batch.steps.transpose(0, 1), batch.edge_index)
    for index, graph in enumerate(graphs):
        alone, _ = lstm(graph.steps.transpose(0, 1), graph.edge_index)
        part = outputs[:, batch.ptr[index]:batch.ptr[index + 1]]
        assert torch.allclose(part, alone, atol=1e-6)


def test_gradients_reach_every_gate():
    graph = sheet_graph(4, 4, 3)
    hidden = 5
    lstm = FCALSTM(3, hidden)
    steps = torch.randn(3, graph.num_nodes, 3)
    outputs, (h, c) = lstm(steps, graph.edge_index)
    (outputs.pow(2).sum() + c.sum()).backward()
    for fused in (lstm.input_maps, lstm.state_maps):
        per_gate = fused.lin.weight.grad.view(4, hidden, -1)
        assert (per_gate.abs().sum(dim=(1, 2)) > 0).all()
        assert (fused.att_src.grad.abs().sum(-1) > 0).all()
    assert (lstm.peephole.grad.abs().sum(-1) > 0).all()


@pytest.mark.parametrize('length', [1, 100])
def test_long_and_short_sequences_stay_finite(length):
    graph = sheet_graph(4, 4, 3)
    lstm = FCALSTM(3, 6)
    steps = 1e3 * torch.randn(length, graph.num_nodes, 3)
    outputs, (h, c) = lstm(steps, graph.edge_index)
    assert torch.isfinite(outputs).all() and torch.isfinite(c).all()
    assert outputs.abs().max() < 1 and c.abs().max() <= length
