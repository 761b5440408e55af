"""The CC0 MakeHuman garments shipped with the package, in the project's frame.

The files are the MakeHuman system clothes fitted onto the hm08 rest body and
split into connected pieces (see ``data/garments/LICENSE_CC0.txt``). hm08 is in
decimetres, +Y up, facing +Z; the project is in metres, +Z up, so a garment
vertex maps as ``(x, y, z) -> (x, -z, y) / 10`` (a proper rotation about +X;
the body then faces -Y).
"""

from __future__ import annotations

from importlib import resources

import numpy as np

from swingar_pyg.geometry.mesh import Mesh, as_mesh, load_mesh

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
