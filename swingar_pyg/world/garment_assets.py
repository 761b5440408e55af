"""The CC0 MakeHuman garments shipped with the package, in the project's frame.

The files are the MakeHuman system clothes fitted onto the hm08 rest body and
split into connected pieces (see ``data/garments/LICENSE_CC0.txt``). hm08 is in
decimetres, +Y up, facing +Z; the project is in metres, +Z up, so a garment
vertex maps as ``(x, y, z) -> (x, -z, y) / 10`` (a proper rotation about +X;
the body then faces -Y).

:func:`fit_shipped_garment` carries a garment onto an anny body of any shape: each
vertex is embedded on the hm08 body surface (in anny's topology: anny keeps 13,718
of hm08's vertices, ``base_mesh_vertex_indices``) and re-evaluated on the anny body.
``data/body/hm08_in_anny_order.npy`` holds those hm08 vertices in anny's order, in
metres, +Z up; :func:`hm08_vertices_in_anny_order` makes it from ``hm08_base.obj``.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import numpy as np
import torch

from swingar_pyg.geometry.edge_collapse import merge_short_edges
from swingar_pyg.geometry.mesh import Mesh, as_mesh, load_mesh
from swingar_pyg.geometry.surface_embedding import embed_points, evaluate_embedding
from swingar_pyg.geometry.weld import weld_mesh
from swingar_pyg.world.body import BodyModel
from swingar_pyg.world.garment import Garment, garment_on_body

_HM08_TO_METRES_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]) / 10.0


def shipped_garments() -> list[str]:
    """Names of the garments shipped with the package."""
    folder = resources.files("swingar_pyg.world") / "data" / "garments"
    return sorted(p.name[:-4] for p in folder.iterdir() if p.name.endswith(".obj"))


def load_shipped_garment(name: str) -> Mesh:
    """A shipped garment in metres, +Z up, fitted on the hm08 rest body."""
    names = shipped_garments()
    if name not in names:
        raise ValueError(f"no shipped garment {name!r}; choose one of {', '.join(names)}")
    resource = resources.files("swingar_pyg.world") / "data" / "garments" / f"{name}.obj"
    with resources.as_file(resource) as path:
        mesh = load_mesh(path)
    return as_mesh(mesh.vertices @ _HM08_TO_METRES_Z_UP.T, mesh.faces)


def hm08_vertices_in_anny_order(hm08_obj: str | Path, base_indices: np.ndarray) -> np.ndarray:
    """The hm08 base mesh's vertices that anny keeps, in anny's order, in metres +Z up.

    Reads the OBJ's ``v`` lines directly: a mesh loader may split vertices at UV
    seams and renumber them.
    """
    with open(hm08_obj) as file:
        vertices = np.array([[float(v) for v in line.split()[1:4]] for line in file
                             if line.startswith("v ")])
    return vertices[np.asarray(base_indices)] @ _HM08_TO_METRES_Z_UP.T


def _hm08_body() -> np.ndarray:
    resource = resources.files("swingar_pyg.world") / "data" / "body" / "hm08_in_anny_order.npy"
    with resources.as_file(resource) as path:
        return np.load(path).astype(np.float64)


def fit_shipped_garment(name: str, body: BodyModel, shape: torch.Tensor,
                        subdivisions: int = 0, merge_edges_below: float = 0.0) -> Garment:
    """A shipped garment carried onto ``body`` with ``shape``, in its rest pose.

    Pinned: the garment's highest boundary loops (waistband, neckline, straps), skinned to
    the torso. The fit attribute is measured on the new body. ``merge_edges_below`` > 0
    welds the mesh and merges its edges shorter than that fraction of the median edge
    length (:func:`~swingar_pyg.geometry.edge_collapse.merge_short_edges`: the shipped
    meshes' sub-millimetre seam edges otherwise take a solver's leftover error as strain).
    ``subdivisions`` then splits every triangle into four that many times (trimesh's
    midpoint subdivision: the same surface at a finer resolution).
    """
    garment = load_shipped_garment(name)
    if merge_edges_below:
        garment = merge_short_edges(weld_mesh(garment)[0], merge_edges_below)[0]
    if subdivisions:
        import trimesh

        vertices, faces = garment.vertices, garment.faces
        for _ in range(subdivisions):
            vertices, faces = trimesh.remesh.subdivide(vertices, faces)
        garment = as_mesh(vertices, faces)
    faces = body.faces.numpy()
    hm08 = _hm08_body()
    if faces.max() >= len(hm08):
        raise ValueError("shipped garments fit bodies with anny's topology only")
    rest = body.rest_vertices(shape).numpy().astype(np.float64)
    # Embedded on hm08 in hm08's frame, evaluated on anny's triangles: the two
    # bodies' different origins cancel.
    embedding = embed_points(garment.vertices, hm08, faces)
    fitted = as_mesh(evaluate_embedding(embedding, rest, faces), garment.faces)
    return garment_on_body(f"makehuman-{name}", fitted, body, shape)
