"""The geometry cases: FCAConv and the spectral descriptor on extreme scales,
low precision, disconnected pieces and degenerate meshes, each measured against
an independent reference (float64, the exact affinity spectrum)."""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor
from torch_geometric.data import Batch, Data

from swingar_pyg.eval.stability.records import Case
from swingar_pyg.geometry import (
    as_mesh,
    exact_affinity_spectrum,
    mesh_edge_index,
    roll_into_cylinder,
    sheet,
    spectral_descriptor,
)
from swingar_pyg.nn import FCAConv

FLOAT32 = 1e-5  # float32 against float64: a few hundred roundoffs of 2^-24
BFLOAT16 = 8 * 2.0**-8  # eight roundoffs of bfloat16's 8-bit significand
FLOAT16 = 8 * 2.0**-11
EXACT = 1e-9  # float64 against float64
NYSTROM = 0.05  # Nyström's top eigenvalues against the exact spectrum


def _sheet_graph(side: int):
    return mesh_edge_index(sheet(side, side, jitter=0.3))


def _inputs(rows: int) -> Tensor:
    # seeded here, so a case's input does not depend on the cases run before it
    return torch.randn(rows, 8, generator=torch.Generator().manual_seed(1))


def _conv():
    torch.manual_seed(0)
    return FCAConv(8, 16, heads=4, alpha=2.0)


def _relative_to_float64(conv, x: Tensor, edge_index: Tensor, dtype: torch.dtype) -> tuple:
    reference = _conv().double()
    reference.load_state_dict(conv.state_dict())
    exact = reference(x.double(), edge_index)
    out = conv.to(dtype)(x.to(dtype), edge_index).double()
    error = float((out - exact).abs().max() / exact.abs().max().clamp_min(1e-300))
    return error, [out]


def _fca_scale(scale: float):
    def run(context):
        edges = _sheet_graph(context.sizes.graph_side)
        x = scale * _inputs(int(edges.max()) + 1)
        return _relative_to_float64(_conv(), x, edges, torch.float32)
    return run


def _fca_precision(dtype: torch.dtype):
    def run(context):
        edges = _sheet_graph(context.sizes.graph_side)
        x = _inputs(int(edges.max()) + 1)
        return _relative_to_float64(_conv(), x, edges, dtype)
    return run


def _fca_isolated(context):
    edges = _sheet_graph(context.sizes.graph_side)
    n = int(edges.max()) + 1
    conv = _conv()
    x = _inputs(n + 10)
    out = conv(x, edges)
    # an isolated vertex attends to itself only: its output is its own message
    own = conv.lin(x[n:]).view(10, 4, 16).mean(1) if not conv.concat else conv.lin(x[n:])
    return float((out[n:] - own - conv.bias).abs().max()), [out]


def _fca_pieces(context):
    edges = _sheet_graph(context.sizes.graph_side)
    small = _sheet_graph(7)
    conv = _conv()
    a, b = _inputs(int(edges.max()) + 1), 1e3 * _inputs(49).flip(0)
    batch = Batch.from_data_list([Data(x=a, edge_index=edges), Data(x=b, edge_index=small)])
    together = conv(batch.x, batch.edge_index)
    alone = torch.cat([conv(a, edges), conv(b, small)])
    scale = alone.abs().amax(dim=1, keepdim=True).clamp_min(1e-30)
    return float(((together - alone) / scale).abs().max()), [together]


def _fca_degenerate(context):
    base = sheet(context.sizes.graph_side, context.sizes.graph_side)
    faces = np.concatenate([base.faces, [[0, 0, 1], [5, 5, 5]]])
    vertices = base.vertices.copy()
    vertices[1] = vertices[0]  # a zero-length edge
    edges = mesh_edge_index(as_mesh(vertices, faces))
    out = _conv()(torch.zeros(len(vertices), 8), edges)  # all-equal (zero) features too
    return float(out.abs().max()), [out]


def _tube(side: int, scale: float = 1.0):
    mesh = roll_into_cylinder(sheet(side, 2 * side, width=1.2, height=0.6, jitter=0.2),
                              radius=0.2)
    return as_mesh(mesh.vertices * scale, mesh.faces)


def _top_error(approximate: np.ndarray, exact: np.ndarray, k: int = 16) -> float:
    k = min(k, len(exact))
    return float(np.max(np.abs(approximate[:k] - exact[:k]) / np.abs(exact[:k]).max()))


def _descriptor_scale(scale: float):
    def run(context):
        unit = spectral_descriptor(_tube(context.sizes.descriptor_side), z=128, sigma=0.1)
        scaled = spectral_descriptor(_tube(context.sizes.descriptor_side, scale), z=128,
                                     sigma=0.1 * scale)
        fixed = spectral_descriptor(_tube(context.sizes.descriptor_side, scale), z=128, sigma=0.1)
        return _top_error(scaled.eigenvalues, unit.eigenvalues), [scaled.eigenvalues,
                                                                   fixed.eigenvalues]
    return run


def _descriptor_small(context):
    mesh = sheet(5, 6)
    descriptor = spectral_descriptor(mesh, z=256, sigma=0.1, return_eigenvectors=True)
    exact, _ = exact_affinity_spectrum(mesh, sigma=0.1)
    return _top_error(descriptor.eigenvalues[:descriptor.num_valid], exact, 30), [
        descriptor.eigenvalues, descriptor.eigenvectors]


def _descriptor_pieces(context):
    side = context.sizes.descriptor_side
    pieces = [_tube(side), sheet(side // 2, side // 2, width=0.3, height=0.3)]
    offset = pieces[0].num_vertices
    union = as_mesh(np.concatenate([pieces[0].vertices, pieces[1].vertices + [5.0, 0, 0]]),
                    np.concatenate([pieces[0].faces, pieces[1].faces + offset]))
    descriptor = spectral_descriptor(union, z=256, sigma=0.1)
    exact = np.sort(np.concatenate([exact_affinity_spectrum(p, sigma=0.1)[0]
                                    for p in pieces]))[::-1]
    return _top_error(descriptor.eigenvalues, exact), [descriptor.eigenvalues]


def _descriptor_degenerate(context):
    tube = _tube(context.sizes.descriptor_side)
    vertices = np.concatenate([tube.vertices, tube.vertices[:1], [[9.0, 9.0, 9.0]]])
    faces = np.concatenate([tube.faces, [[0, 0, 1], [2, 2, 2]]])
    mesh = as_mesh(vertices, faces)  # a duplicate vertex, an isolated one, zero-area faces
    descriptor = spectral_descriptor(mesh, z=256, sigma=0.1, return_eigenvectors=True)
    exact, _ = exact_affinity_spectrum(mesh, sigma=0.1)
    return _top_error(descriptor.eigenvalues, exact), [descriptor.eigenvalues,
                                                       descriptor.eigenvectors]


FCACONV_CASES: tuple[Case, ...] = (
    Case("FCAConv", "input x 1e-3", "max relative error vs float64", _fca_scale(1e-3),
         bound=FLOAT32),
    Case("FCAConv", "input x 1e3", "max relative error vs float64", _fca_scale(1e3),
         bound=FLOAT32),
    Case("FCAConv", "bfloat16", "max relative error vs float64", _fca_precision(torch.bfloat16),
         bound=BFLOAT16),
    Case("FCAConv", "float16", "max relative error vs float64", _fca_precision(torch.float16),
         bound=FLOAT16),
    Case("FCAConv", "isolated vertices", "max |output - own message|", _fca_isolated,
         bound=FLOAT32),
    Case("FCAConv", "disconnected pieces (1 : 1e3 scale)", "max relative gap Batch vs alone",
         _fca_pieces, bound=FLOAT32),
    Case("FCAConv", "zero-area faces, zero features", "max |output|", _fca_degenerate,
         bound=FLOAT32),
)

DESCRIPTOR_CASES: tuple[Case, ...] = (
    Case("descriptor", "scale 1e-3 (sigma scaled)", "top-16 error vs unit scale",
         _descriptor_scale(1e-3), bound=EXACT),
    Case("descriptor", "scale 1e3 (sigma scaled)", "top-16 error vs unit scale",
         _descriptor_scale(1e3), bound=EXACT),
    Case("descriptor", "N < z (30 vertices, z = 256)", "error vs exact spectrum",
         _descriptor_small, bound=EXACT),
    Case("descriptor", "disconnected pieces", "top-16 error vs exact spectra", _descriptor_pieces,
         bound=NYSTROM),
    Case("descriptor", "duplicate + isolated vertex, zero-area faces", "top-16 error vs exact",
         _descriptor_degenerate, bound=NYSTROM),
)
