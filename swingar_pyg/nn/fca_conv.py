import warnings
from typing import Optional, Tuple, Union

import torch
import torch.nn.functional as F
from torch import Tensor
from torch.nn import Parameter
from torch_geometric import EdgeIndex
from torch_geometric.nn.conv import MessagePassing
from torch_geometric.nn.dense.linear import Linear
from torch_geometric.nn.inits import glorot, zeros
from torch_geometric.typing import Adj, OptPairTensor, OptTensor, Size
from torch_geometric.utils import (
    add_self_loops,
    is_torch_sparse_tensor,
    remove_self_loops,
    scatter,
    segment,
    softmax,
)
from torch_geometric.utils.sparse import set_sparse_value

# Added to the squared bound under the square root: keeps the gradient finite when every
# feature of a neighbourhood is zero (all scores are then zero and attention is uniform).
# A normal float32 far below any real feature scale, so it does not break scale invariance.
_SQUARED_NORM_FLOOR = 1e-30

# Scores are bounded, so below this bound on |LeakyReLU(e*)| the softmax needs no
# max-shift: exp stays within [e^-60, e^60] (far inside float32), which saves a
# scatter-max per call.
_UNSHIFTED_SOFTMAX_MAX_SCORE = 60.0


class FCAConv(MessagePassing):
    r"""The frequency-controllable attention operator from the `"SwinGar:
    Spectrum-Inspired Neural Dynamic Deformation for Free-Swinging Garments"
    <https://arxiv.org/abs/2308.02827>`_ paper: a graph attention layer whose
    scores are Lipschitz-normalised (`"Lipschitz Normalization for Self-Attention
    Layers with Application to Graph Neural Networks"
    <https://arxiv.org/abs/2103.04886>`_) and scaled by :math:`\alpha`.

    .. math::
        \mathbf{x}^{\prime}_i = \sum_{j \in \mathcal{N}(i) \cup \{ i \}}
        \alpha_{i,j}\mathbf{h}_{j}, \qquad \mathbf{h}_j = \mathbf{\Theta}\mathbf{x}_j,

    where, with the GAT score
    :math:`e_{i,j} = \mathbf{a}_t^{\top}\mathbf{h}_i + \mathbf{a}_s^{\top}\mathbf{h}_j`,
    the attention coefficients are

    .. math::
        e^{*}_{i,j} = \frac{\alpha \, e_{i,j}}
        {\left\| [\mathbf{a}_t \,\Vert\, \mathbf{a}_s] \right\|_2 \,
        \max_{k \in \mathcal{N}(i) \cup \{ i \}}
        \left\| [\mathbf{h}_i \,\Vert\, \mathbf{h}_k] \right\|_2},
        \qquad
        \alpha_{i,j} = \frac{\exp\left(\mathrm{LeakyReLU}(e^{*}_{i,j})\right)}
        {\sum_{k \in \mathcal{N}(i) \cup \{ i \}}
        \exp\left(\mathrm{LeakyReLU}(e^{*}_{i,k})\right)}.

    By Cauchy–Schwarz :math:`|e^{*}_{i,j}| \leq \alpha`, so every weight lies in
    :math:`[e^{-(1+s)\alpha}/d_i,\; e^{(1+s)\alpha}/d_i]` for LeakyReLU slope
    :math:`s` and in-degree :math:`d_i`. :math:`\alpha` therefore bounds how far
    the layer departs from mean aggregation, i.e. how much high-frequency content
    of the graph signal it can pass: :math:`\alpha = 0` is exactly the mean over
    :math:`\mathcal{N}(i) \cup \{ i \}` (a pure low-pass filter). The attention is
    invariant to rescaling the input, and the layer is positively homogeneous of
    degree one (without bias), so its Lipschitz constant does not grow with the
    scale of the input, unlike GAT's.

    The maximum is taken per destination node over its incoming edges, so a graph
    gives the same output alone or inside a :class:`~torch_geometric.data.Batch`.
    Scores are computed in at least :obj:`float32`, so half-precision inputs do not
    overflow the norms. Because the scores are bounded, the softmax needs no
    max-shift for stability (for :math:`\alpha \max(1, s) \leq 60`), which
    saves a scatter-max. Given an :class:`~torch_geometric.EdgeIndex` sorted by
    destination (and :obj:`add_self_loops=False`), the neighbourhood maximum is a
    segment reduction and, when no gradient is needed (inference) in
    :obj:`float32` or :obj:`float64`, the aggregation is one sparse CSR product per
    head, :math:`\mathbf{X}'_{:,h} = \mathbf{A}_h \mathbf{H}_{:,h}` with
    :math:`(\mathbf{A}_h)_{ij} = \alpha_{i,j,h}`, instead of materialising
    :math:`|\mathcal{E}| \cdot H \cdot F_{out}` messages (``fused_aggregation``).

    Args:
        in_channels (int or tuple): Size of each input sample, or :obj:`-1` to
            derive the size from the first input(s) to the forward method.
            A tuple corresponds to the sizes of source and target
            dimensionalities in case of a bipartite graph.
        out_channels (int): Size of each output sample.
        heads (int, optional): Number of multi-head-attentions.
            (default: :obj:`1`)
        concat (bool, optional): If set to :obj:`False`, the multi-head
            attentions are averaged instead of concatenated.
            (default: :obj:`True`)
        alpha (float, optional): The bound :math:`\alpha \geq 0` on the
            normalised score. Ignored if :obj:`normalize=False`.
            (default: :obj:`2.0`)
        normalize (bool, optional): If set to :obj:`False`, uses the plain GAT
            score :math:`e_{i,j}` (the layer is then :class:`GATConv`).
            (default: :obj:`True`)
        negative_slope (float, optional): LeakyReLU angle of the negative
            slope. (default: :obj:`0.2`)
        dropout (float, optional): Dropout probability of the normalized
            attention coefficients. (default: :obj:`0`)
        add_self_loops (bool, optional): If set to :obj:`False`, will not add
            self-loops to the input graph. Pass graphs with self-loops already
            added and :obj:`False` here for :meth:`torch.compile` without graph
            breaks. (default: :obj:`True`)
        bias (bool, optional): If set to :obj:`False`, the layer will not learn
            an additive bias. (default: :obj:`True`)
        fused_aggregation (bool, optional): Aggregate with sparse CSR products
            where that applies (see above); :obj:`False` always runs
            :meth:`message` and a scatter. Both give the same output.
            (default: :obj:`True`)
        **kwargs (optional): Additional arguments of
            :class:`torch_geometric.nn.conv.MessagePassing`.

    Shapes:
        - **input:**
          node features :math:`(|\mathcal{V}|, F_{in})` or
          :math:`((|\mathcal{V_s}|, F_{s}), (|\mathcal{V_t}|, F_{t}))`
          if bipartite,
          edge indices :math:`(2, |\mathcal{E}|)` or a :obj:`torch.sparse`
          adjacency :math:`(|\mathcal{V_t}|, |\mathcal{V_s}|)`
        - **output:** node features :math:`(|\mathcal{V}|, H * F_{out})` or
          :math:`((|\mathcal{V}_t|, H * F_{out})` if bipartite.
          If :obj:`return_attention_weights=True`, then
          :math:`((|\mathcal{V}|, H * F_{out}),
          ((2, |\mathcal{E}|), (|\mathcal{E}|, H)))`
          or :math:`((|\mathcal{V_t}|, H * F_{out}), ((2, |\mathcal{E}|),
          (|\mathcal{E}|, H)))` if bipartite
    """
    def __init__(
        self,
        in_channels: Union[int, Tuple[int, int]],
        out_channels: int,
        heads: int = 1,
        concat: bool = True,
        alpha: float = 2.0,
        normalize: bool = True,
        negative_slope: float = 0.2,
        dropout: float = 0.0,
        add_self_loops: bool = True,
        bias: bool = True,
        fused_aggregation: bool = True,
        **kwargs,
    ):
        if alpha < 0:
            raise ValueError(f"'alpha' must be non-negative, got {alpha}")
        kwargs.setdefault('aggr', 'add')
        super().__init__(node_dim=0, **kwargs)

        self.in_channels = in_channels
        self.out_channels = out_channels
        self.heads = heads
        self.concat = concat
        self.alpha = float(alpha)
        self.normalize = normalize
        self.negative_slope = negative_slope
        self.dropout = dropout
        self.add_self_loops = add_self_loops
        self.fused_aggregation = fused_aggregation

        self.lin = self.lin_src = self.lin_dst = None
        if isinstance(in_channels, int):
            self.lin = Linear(in_channels, heads * out_channels, bias=False,
                              weight_initializer='glorot')
        else:
            self.lin_src = Linear(in_channels[0], heads * out_channels, False,
                                  weight_initializer='glorot')
            self.lin_dst = Linear(in_channels[1], heads * out_channels, False,
                                  weight_initializer='glorot')

        self.att_src = Parameter(torch.empty(1, heads, out_channels))
        self.att_dst = Parameter(torch.empty(1, heads, out_channels))

        if bias:
            self.bias = Parameter(
                torch.empty(heads * out_channels if concat else out_channels))
        else:
            self.register_parameter('bias', None)

        self.reset_parameters()

    def reset_parameters(self):
        super().reset_parameters()
        for lin in (self.lin, self.lin_src, self.lin_dst):
            if lin is not None:
                lin.reset_parameters()
        glorot(self.att_src)
        glorot(self.att_dst)
        zeros(self.bias)

    def forward(
        self,
        x: Union[Tensor, OptPairTensor],
        edge_index: Adj,
        size: Size = None,
        return_attention_weights: Optional[bool] = None,
    ) -> Union[Tensor, Tuple[Tensor, Tuple[Tensor, Tensor]]]:
        r"""Runs the forward pass of the module.

        Args:
            x (torch.Tensor or (torch.Tensor, torch.Tensor)): The input node
                features.
            edge_index (torch.Tensor): The edge indices, or a
                :obj:`torch.sparse` adjacency matrix.
            size ((int, int), optional): The shape of the adjacency matrix.
                (default: :obj:`None`)
            return_attention_weights (bool, optional): If set, additionally
                returns the tuple :obj:`(edge_index, attention_weights)`.
                (default: :obj:`None`)
        """
        H, C = self.heads, self.out_channels

        if isinstance(x, Tensor):
            if self.lin is not None:
                x_src = x_dst = self.lin(x).view(-1, H, C)
            else:
                assert self.lin_src is not None and self.lin_dst is not None
                x_src = self.lin_src(x).view(-1, H, C)
                x_dst = self.lin_dst(x).view(-1, H, C)
        else:
            x_src, x_dst = x
            if self.lin is not None:
                x_src = self.lin(x_src).view(-1, H, C)
                if x_dst is not None:
                    x_dst = self.lin(x_dst).view(-1, H, C)
            else:
                assert self.lin_src is not None and self.lin_dst is not None
                x_src = self.lin_src(x_src).view(-1, H, C)
                if x_dst is not None:
                    x_dst = self.lin_dst(x_dst).view(-1, H, C)

        # Node-level score terms (and, for the Lipschitz bound, squared norms)
        # in at least float32, so that half-precision norms cannot overflow:
        score_dtype = torch.promote_types(x_src.dtype, torch.float32)
        h_src = x_src.to(score_dtype)
        score_src = (h_src * self.att_src.to(score_dtype)).sum(dim=-1)
        sq_norm_src = h_src.square().sum(dim=-1) if self.normalize else None
        score_dst = sq_norm_dst = None
        if x_dst is not None:
            h_dst = x_dst.to(score_dtype)
            score_dst = (h_dst * self.att_dst.to(score_dtype)).sum(dim=-1)
            if self.normalize:
                sq_norm_dst = h_dst.square().sum(dim=-1)

        if self.add_self_loops:
            if isinstance(edge_index, Tensor):  # also torch.sparse
                num_nodes = x_src.size(0)
                if x_dst is not None:
                    num_nodes = min(num_nodes, x_dst.size(0))
                num_nodes = min(size) if size is not None else num_nodes
                edge_index, _ = remove_self_loops(edge_index)
                edge_index, _ = add_self_loops(edge_index,
                                               num_nodes=num_nodes)
            else:
                raise ValueError(
                    "FCAConv adds self-loops to 'edge_index' tensors and "
                    "torch.sparse adjacencies only; convert a SparseTensor "
                    "with '.to_torch_sparse_csr_tensor()' or pass "
                    "'add_self_loops=False'")

        alpha = self.edge_updater(edge_index, score=(score_src, score_dst),
                                  sq_norm=(sq_norm_src, None),
                                  sq_norm_dst=sq_norm_dst, size=size)
        alpha = alpha.to(x_src.dtype)
        if self._aggregates_fused(edge_index, x_src, x_dst, alpha, size):
            out = self._csr_aggregate(edge_index, x_src, alpha)
        else:
            out = self.propagate(edge_index, x=(x_src, x_dst), alpha=alpha,
                                 size=size)

        if self.concat:
            out = out.view(-1, self.heads * self.out_channels)
        else:
            out = out.mean(dim=1)

        if self.bias is not None:
            out = out + self.bias

        if return_attention_weights:
            if is_torch_sparse_tensor(edge_index):
                adj = set_sparse_value(edge_index, alpha)
                return out, (adj, alpha)
            return out, (edge_index, alpha)
        return out

    def edge_update(self, score_j: Tensor, score_i: OptTensor,
                    sq_norm_j: OptTensor, sq_norm_dst: OptTensor, index: Tensor,
                    ptr: OptTensor, dim_size: Optional[int]) -> Tensor:
        score = score_j if score_i is None else score_j + score_i
        if self.normalize and sq_norm_j is not None and index.numel() > 0:
            scale = self._score_scale(sq_norm_j, sq_norm_dst, index, ptr, dim_size)
            score = score * scale.index_select(0, index)
        score = F.leaky_relu(score, self.negative_slope)
        if self.normalize and self.alpha * max(1.0, abs(
                self.negative_slope)) <= _UNSHIFTED_SOFTMAX_MAX_SCORE:
            weight = score.exp()
            total = scatter(weight, index, dim=0, dim_size=dim_size, reduce='sum')
            alpha = weight / total.index_select(0, index)
        else:
            alpha = softmax(score, index, ptr, dim_size)
        return F.dropout(alpha, p=self.dropout, training=self.training)

    def _score_scale(self, sq_norm_j: Tensor, sq_norm_dst: OptTensor,
                     index: Tensor, ptr: OptTensor,
                     dim_size: Optional[int]) -> Tensor:
        r"""Per destination node and head, :math:`\alpha` divided by the
        Cauchy–Schwarz bound :math:`\|[\mathbf{a}_t \Vert \mathbf{a}_s]\|
        \sqrt{\|\mathbf{h}_i\|^2 + \max_{k} \|\mathbf{h}_k\|^2}`."""
        dtype = sq_norm_j.dtype
        att_sq_norm = self.att_src.to(dtype).square().sum(dim=-1)
        if ptr is not None:  # edges sorted by destination: a segment reduction
            neighbour_sq_max = segment(sq_norm_j, ptr, reduce='max')
        else:
            neighbour_sq_max = scatter(sq_norm_j, index, dim=0,
                                       dim_size=dim_size, reduce='max')
        if sq_norm_dst is not None:
            att_sq_norm = att_sq_norm + self.att_dst.to(dtype).square().sum(-1)
            neighbour_sq_max = neighbour_sq_max + sq_norm_dst
        # alpha / sqrt(.) rather than rsqrt: the derivative of rsqrt at the floor
        # overflows float32, those of 1/x and sqrt do not.
        return self.alpha / torch.sqrt(att_sq_norm * neighbour_sq_max +
                                       _SQUARED_NORM_FLOOR)

    def _aggregates_fused(self, edge_index: Adj, x_src: Tensor,
                          x_dst: OptTensor, alpha: Tensor, size: Size) -> bool:
        return (self.fused_aggregation and size is None
                and isinstance(edge_index, EdgeIndex)
                and edge_index.is_sorted_by_col
                and (x_dst is None or x_dst.size(0) == x_src.size(0))
                and x_src.dtype in (torch.float32, torch.float64)
                and not (torch.is_grad_enabled() and
                         (x_src.requires_grad or alpha.requires_grad))
                and not torch.compiler.is_compiling())

    def _csr_aggregate(self, edge_index: EdgeIndex, x_src: Tensor,
                       alpha: Tensor) -> Tensor:
        (ptr, source), _ = edge_index.get_csc()
        shape = (x_src.size(0), x_src.size(0))
        with warnings.catch_warnings():  # torch's note that CSR tensors are beta
            warnings.filterwarnings('ignore', 'Sparse CSR tensor support')
            return torch.stack([
                torch.sparse_csr_tensor(ptr, source, alpha[:, h].contiguous(),
                                        shape, check_invariants=False)
                @ x_src[:, h] for h in range(self.heads)
            ], dim=1)

    def message(self, x_j: Tensor, alpha: Tensor) -> Tensor:
        return alpha.unsqueeze(-1) * x_j

    def __repr__(self) -> str:
        scale = f'alpha={self.alpha}' if self.normalize else 'normalize=False'
        return (f'{self.__class__.__name__}({self.in_channels}, '
                f'{self.out_channels}, heads={self.heads}, {scale})')
