from typing import Optional, Sequence, Tuple, Union

import torch
from torch import Tensor
from torch.nn import Module, Parameter
from torch_geometric.utils import add_remaining_self_loops

from swingar_pyg.nn.fca_conv import FCAConv

LSTMState = Tuple[Tensor, Tensor]

# Gate order of the four attention heads of each FCA map.
_GATES = ('input', 'forget', 'cell', 'output')


class FCALSTM(Module):
    r"""A graph LSTM whose input-to-state and state-to-state maps are
    :class:`FCAConv` layers, from the `"SwinGar: Spectrum-Inspired Neural Dynamic
    Deformation for Free-Swinging Garments" <https://arxiv.org/abs/2308.02827>`_
    paper (eq. 6), in the peephole form of ConvLSTM:

    .. math::
        \mathbf{i}_t &= \sigma\left(\mathcal{F}_{xi}(\mathbf{X}_t) +
        \mathcal{F}_{hi}(\mathbf{H}_{t-1}) + \mathbf{w}_i \odot
        \mathbf{C}_{t-1} + \mathbf{b}_i\right)

        \mathbf{f}_t &= \sigma\left(\mathcal{F}_{xf}(\mathbf{X}_t) +
        \mathcal{F}_{hf}(\mathbf{H}_{t-1}) + \mathbf{w}_f \odot
        \mathbf{C}_{t-1} + \mathbf{b}_f\right)

        \mathbf{C}_t &= \mathbf{f}_t \odot \mathbf{C}_{t-1} + \mathbf{i}_t
        \odot \tanh\left(\mathcal{F}_{xc}(\mathbf{X}_t) +
        \mathcal{F}_{hc}(\mathbf{H}_{t-1}) + \mathbf{b}_c\right)

        \mathbf{o}_t &= \sigma\left(\mathcal{F}_{xo}(\mathbf{X}_t) +
        \mathcal{F}_{ho}(\mathbf{H}_{t-1}) + \mathbf{w}_o \odot
        \mathbf{C}_t + \mathbf{b}_o\right)

        \mathbf{H}_t &= \mathbf{o}_t \odot \tanh(\mathbf{C}_t)

    where each :math:`\mathcal{F}` is a frequency-controllable attention map
    over the same graph. The four input maps are the four heads of one
    :class:`FCAConv` (each head has its own weights and attention, so this is
    exactly four separate layers), likewise the four state maps. The forget
    bias starts at one. Since :math:`|\mathbf{C}_t| \leq |\mathbf{C}_{t-1}| + 1`
    and :math:`|\mathbf{H}_t| < 1`, states stay finite over any sequence length.

    Args:
        in_channels (int): Size of each input node feature.
        hidden_channels (int): Size of the hidden and cell states.
        alpha (float, optional): :math:`\alpha` of every :class:`FCAConv`.
            (default: :obj:`2.0`)
        normalize (bool, optional): Lipschitz normalisation of the attention
            scores (:obj:`False` gives GAT maps). (default: :obj:`True`)
        add_self_loops (bool, optional): Add self-loops to the graph once per
            call. (default: :obj:`True`)

    Shapes:
        - **input:** node features :math:`(T, |\mathcal{V}|, F_{in})` or a
          sequence of :math:`T` tensors :math:`(|\mathcal{V}|, F_{in})`, edge
          indices :math:`(2, |\mathcal{E}|)`, optional state
          :math:`((|\mathcal{V}|, F_{hid}), (|\mathcal{V}|, F_{hid}))`
        - **output:** hidden states :math:`(T, |\mathcal{V}|, F_{hid})` and the
          final state :math:`((|\mathcal{V}|, F_{hid}), (|\mathcal{V}|, F_{hid}))`
    """
    def __init__(self, in_channels: int, hidden_channels: int,
                 alpha: float = 2.0, normalize: bool = True,
                 add_self_loops: bool = True):
        super().__init__()
        self.in_channels = in_channels
        self.hidden_channels = hidden_channels
        self.add_self_loops = add_self_loops
        gates = len(_GATES)
        self.input_maps = FCAConv(in_channels, hidden_channels, heads=gates,
                                  alpha=alpha, normalize=normalize,
                                  add_self_loops=False, bias=True)
        self.state_maps = FCAConv(hidden_channels, hidden_channels,
                                  heads=gates, alpha=alpha,
                                  normalize=normalize, add_self_loops=False,
                                  bias=False)
        self.peephole = Parameter(torch.empty(3, hidden_channels))
        self.reset_parameters()

    def reset_parameters(self):
        self.input_maps.reset_parameters()
        self.state_maps.reset_parameters()
        torch.nn.init.zeros_(self.peephole)
        with torch.no_grad():
            bias = self.input_maps.bias.view(len(_GATES), self.hidden_channels)
            bias[_GATES.index('forget')].fill_(1.0)

    def forward(
        self,
        x: Union[Tensor, Sequence[Tensor]],
        edge_index: Tensor,
        state: Optional[LSTMState] = None,
    ) -> Tuple[Tensor, LSTMState]:
        steps = torch.stack(list(x)) if not isinstance(x, Tensor) else x
        if steps.dim() != 3 or steps.size(0) == 0:
            raise ValueError(
                f"FCALSTM expects node features of shape (T, N, F) with T >= 1, "
                f"got {tuple(steps.shape)}")
        num_nodes = steps.size(1)
        if self.add_self_loops:
            edge_index, _ = add_remaining_self_loops(edge_index,
                                                     num_nodes=num_nodes)
        h_c: Optional[LSTMState] = state
        outputs = []
        for x_t in steps:
            h_c = self.step_from_input_terms(self.input_terms(x_t, edge_index),
                                             edge_index, h_c)
            outputs.append(h_c[0])
        assert h_c is not None
        return torch.stack(outputs), h_c

    def input_terms(self, x: Tensor, edge_index: Tensor) -> Tensor:
        r"""The input maps of one step, :math:`[\mathcal{F}_{xi}(\mathbf{X}_t)
        \Vert \dots \Vert \mathcal{F}_{xo}(\mathbf{X}_t)] + \mathbf{b}`,
        :math:`(|\mathcal{V}|, 4 F_{hid})`. They depend on :math:`\mathbf{X}_t`
        alone, so a stream that sees each input in several windows computes
        them once."""
        return self.input_maps(x, edge_index)

    def step(self, x: Tensor, edge_index: Tensor,
             state: Optional[LSTMState] = None) -> LSTMState:
        r"""One LSTM step on a graph whose self-loops are already in
        :obj:`edge_index`; returns :math:`(\mathbf{H}_t, \mathbf{C}_t)`.
        :obj:`None` is the zero state."""
        return self.step_from_input_terms(self.input_terms(x, edge_index),
                                          edge_index, state)

    def step_from_input_terms(self, input_terms: Tensor, edge_index: Tensor,
                              state: Optional[LSTMState] = None) -> LSTMState:
        r""":meth:`step` given the step's :meth:`input_terms`. From the zero
        state (:obj:`None`) the state maps are skipped: without a bias they map
        zero to zero."""
        pre = input_terms
        if state is None:
            zero = input_terms.new_zeros(input_terms.size(0),
                                         self.hidden_channels)
            h, c = zero, zero
        else:
            h, c = state
            pre = pre + self.state_maps(h, edge_index)
        pre_i, pre_f, pre_c, pre_o = pre.view(
            -1, len(_GATES), self.hidden_channels).unbind(dim=1)
        w_i, w_f, w_o = self.peephole.unbind(dim=0)
        i = torch.sigmoid(pre_i + w_i * c)
        f = torch.sigmoid(pre_f + w_f * c)
        c = f * c + i * torch.tanh(pre_c)
        o = torch.sigmoid(pre_o + w_o * c)
        return o * torch.tanh(c), c

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.in_channels}, '
                f'{self.hidden_channels}, alpha={self.input_maps.alpha})')
