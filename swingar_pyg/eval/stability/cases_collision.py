"""The collision cases: a garment entirely inside the body, deep collisions
from extreme poses and coordinates 1e3x larger, each corrected and measured by
the share of vertices still inside, against the exact signed distance."""

from __future__ import annotations

import torch
from torch import Tensor

from swingar_pyg.collision import exact_signed_distance, resolve_collisions
from swingar_pyg.eval.stability.records import Case

SURFACE_TOLERANCE = 1e-6
"""A corrected vertex counts as inside the body when deeper than this (1 µm): one
moved onto the surface lands on either side of it by rounding alone."""

INSIDE_PERCENT = 0.5


def _collide(context, vertices: Tensor, posed_index: int, posed) -> tuple:
    exact = exact_signed_distance(posed.vertices[posed_index], context.body.faces)
    if context.neural is not None:
        result = context.neural.correct(vertices.float(), context.graph.edge_index,
                                        posed.joint_transforms[posed_index],
                                        posed.joint_positions[posed_index])
        sdf = "neural SDF"
    else:
        result = resolve_collisions(vertices.double(), context.graph.edge_index, exact)
        sdf = "exact SDF"
    before = float((exact(vertices.double())[0] > 0).float().mean())
    depth = exact(result.vertices.double())[0]
    after = float((depth > SURFACE_TOLERANCE).float().mean())
    return 100 * after, [result.vertices], (f"{sdf}; inside before {100 * before:.1f} %, "
                                            f"deepest after {1e3 * float(depth.max()):.3g} mm")


def _collision_inside(context):
    # the skirt shrunk onto the body's axis: every vertex deep inside
    clip = context.motion("sway", 0.1)
    posed = context.body.pose(context.shape, clip.rotations[:1], clip.translation[:1])
    rest = context.graph.rest
    centre = rest.mean(0)
    inside = centre + 0.3 * (rest - centre) * torch.tensor([1.0, 1.0, 0.0]) + \
        (rest - centre) * torch.tensor([0.0, 0.0, 1.0])
    return _collide(context, inside, 0, posed)


def _collision_extreme(kind: str, seconds: float):
    def run(context):
        # The skirt carried by the hips alone while the legs split or the arms cross
        # through it: as deep a collision as a badly skinned garment meets.
        clip = context.motion(kind, 2.0)
        frame = round(seconds * clip.fps)
        posed = context.body.pose(context.shape, clip.rotations, clip.translation)
        hips = posed.joint_transforms[frame, 0]
        carried = context.graph.rest @ hips[:3, :3].T + hips[:3, 3]
        return _collide(context, carried, frame, posed)
    return run


def _collision_scale(context):
    def ball(points):  # a sphere of radius 1 km, positive inside
        norm = points.norm(dim=-1, keepdim=True)
        return 1e3 - norm[:, 0], -points / norm.clamp_min(1e-300)

    rest = context.graph.rest.double() * 1e3
    result = resolve_collisions(rest - rest.mean(0), context.graph.edge_index, ball)
    inside = ball(result.vertices)[0] > 1e3 * SURFACE_TOLERANCE
    return 100 * float(inside.float().mean()), [result.vertices]


COLLISION_CASES: tuple[Case, ...] = (
    Case("collisions", "garment entirely inside", "% over 1 µm inside after", _collision_inside,
         bound=INSIDE_PERCENT),
    Case("collisions", "legs split through a hip-carried skirt", "% over 1 µm inside after",
         _collision_extreme("leg_split", 0.5), bound=INSIDE_PERCENT),
    Case("collisions", "front split through a hip-carried skirt", "% over 1 µm inside after",
         _collision_extreme("leg_split", 1.5), bound=INSIDE_PERCENT),
    Case("collisions", "coordinates x 1e3", "% over 1 mm inside after (x 1e3)", _collision_scale,
         bound=INSIDE_PERCENT),
)
