"""Small garment-like graphs for the tests."""

import torch
from torch_geometric.data import Data

from swingar_pyg.geometry import mesh_edge_index, sheet


def sheet_graph(rows: int, cols: int, channels: int, jitter: float = 0.0, seed: int = 0) -> Data:
    mesh = sheet(rows, cols, jitter=jitter, seed=seed)
    generator = torch.Generator().manual_seed(seed)
    x = torch.randn(mesh.num_vertices, channels, generator=generator)
    return Data(x=x, edge_index=mesh_edge_index(mesh))
