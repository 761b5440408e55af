"""Graphs prepared once for attention layers."""

from typing import Optional

import torch
from torch import Tensor
from torch_geometric import EdgeIndex
from torch_geometric.utils import add_remaining_self_loops


def attention_edge_index(edge_index: Tensor,
                         num_nodes: Optional[int] = None) -> EdgeIndex:
    r"""Adds a self-loop to every node and sorts the edges by destination.

    Prepare a graph this way once (e.g. per garment, before batching; a
    :class:`~torch_geometric.data.Batch` keeps the order) and run
    :class:`FCAConv` or :class:`GATConv` with :obj:`add_self_loops=False`: the
    layers then skip the self-loop bookkeeping on every call and reduce
    neighbourhoods as contiguous segments, which makes :class:`FCAConv`'s
    forward and backward closer to :class:`GATConv`'s. For :meth:`torch.compile`,
    which does not trace the :class:`~torch_geometric.EdgeIndex` subclass, pass
    :meth:`EdgeIndex.as_tensor` of the result.

    Args:
        edge_index (torch.Tensor): The edge indices :math:`(2, |\mathcal{E}|)`.
        num_nodes (int, optional): The number of nodes; inferred from
            :obj:`edge_index` if not given. (default: :obj:`None`)
    """
    if num_nodes is None:
        num_nodes = int(edge_index.max()) + 1 if edge_index.numel() > 0 else 0
    loops, _ = add_remaining_self_loops(edge_index, num_nodes=num_nodes)
    order = torch.argsort(loops[1] * num_nodes + loops[0])
    return EdgeIndex(loops[:, order], sparse_size=(num_nodes, num_nodes),
                     sort_order='col')
