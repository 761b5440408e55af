"""A stack of FCA layers: per-vertex features of a mesh graph (SwinGar's garment
encoder :math:`M_g`, state encoder and predictor)."""

from __future__ import annotations

import torch.nn.functional as F
from torch import Tensor, nn

from swingar_pyg.nn.fca_conv import FCAConv


class FCAStack(nn.Module):
    r"""``layers`` :class:`FCAConv` layers, each followed by ELU, with attention
    heads averaged:

    .. math::
        \mathbf{h}^{(l+1)} = \mathrm{ELU}\left(\mathrm{FCA}^{(l)}(\mathbf{h}^{(l)})\right),
        \qquad \mathbf{h}^{(0)} = \mathbf{x}.

    Args:
        in_channels (int): Size of each input feature.
        channels (int): Size of every layer's output.
        layers (int): Number of FCA layers.
        heads (int, optional): Attention heads per layer, averaged. (default: :obj:`1`)
        alpha (float, optional): The score bound of every layer. (default: :obj:`2.0`)
        normalize (bool, optional): Lipschitz-normalised scores (:obj:`False` gives
            GAT layers). (default: :obj:`True`)
        add_self_loops (bool, optional): Let each layer add self-loops; pass
            :obj:`False` when the graph already has them. (default: :obj:`True`)
    """

    def __init__(self, in_channels: int, channels: int, layers: int, heads: int = 1,
                 alpha: float = 2.0, normalize: bool = True, add_self_loops: bool = True):
        super().__init__()
        sizes = [in_channels] + [channels] * layers
        self.layers = nn.ModuleList(
            FCAConv(a, b, heads=heads, concat=False, alpha=alpha, normalize=normalize,
                    add_self_loops=add_self_loops) for a, b in zip(sizes[:-1], sizes[1:]))

    def forward(self, x: Tensor, edge_index: Tensor) -> Tensor:
        for layer in self.layers:
            x = F.elu(layer(x, edge_index))
        return x
