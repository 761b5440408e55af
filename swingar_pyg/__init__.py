"""swingar_pyg: SwinGar for PyTorch Geometric.

Importing the package is cheap; sub-packages are imported where they are used, so that
``from swingar_pyg.nn import FCAConv`` needs nothing but torch and torch_geometric.
"""

__version__ = "0.1.0"
