"""Graph layers of SwinGar. Needs only torch and torch_geometric."""

from swingar_pyg.nn.attention_graph import attention_edge_index
from swingar_pyg.nn.fca_conv import FCAConv
from swingar_pyg.nn.fca_lstm import FCALSTM
from swingar_pyg.nn.fca_stack import FCAStack

__all__ = ["FCAConv", "FCALSTM", "FCAStack", "attention_edge_index"]
