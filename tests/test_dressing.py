import numpy as np
import torch

from swingar_pyg.sim import STRETCH_BAR, XPBDSettings

from .extras import require


def test_shipped_trousers_are_dressed_off_the_contact_layer_and_rest_unstretched():
    require('anny')
    from swingar_pyg.geometry import BodySurface
    from swingar_pyg.world.body import AnnyBody
    from swingar_pyg.world.garment import DRESSING_CLEARANCE
    from swingar_pyg.world.garment_assets import fit_shipped_garment
    from swingar_pyg.world.motion import procedural_motion
    from swingar_pyg.world.sequence import simulate_sequence

    body = AnnyBody()
    shape = body.default_shape()
    trousers = fit_shipped_garment('trousers', body, shape)  # its cuffs touch the ankles
    surface = BodySurface(body.rest_vertices(shape).double().numpy(), body.faces.numpy())
    depth, _ = surface.signed_distance(trousers.mesh.vertices)
    assert (-depth).min() > DRESSING_CLEARANCE - 1e-6 > XPBDSettings.thickness
    # standing still: a cuff that started inside the contact layer was stretched 15 % open
    motion = procedural_motion('sway', body.joint_names, seconds=0.3, amplitude=0.0)
    settings = XPBDSettings(fps=motion.fps, substeps=100, iterations=1, backend='warp',
                            bend_every=10)
    result = simulate_sequence(body, shape, trousers, motion, settings).result
    assert torch.isfinite(result.positions).all()
    assert np.max(result.max_stretch) < STRETCH_BAR


def test_shipped_shorts_with_their_short_edges_merged_stand_unstretched():
    """The shipped shorts' sub-millimetre seam edges take the solver's leftover error as
    strain even standing still; merged (edges under half the median), they rest within
    the bar, with the same topology and their pins on the waistband."""
    require('anny')
    import trimesh

    from swingar_pyg.world.body import AnnyBody
    from swingar_pyg.world.catalogue import ShippedGarmentSpec, fit_garment
    from swingar_pyg.world.motion import procedural_motion
    from swingar_pyg.world.sequence import simulate_sequence

    body = AnnyBody()
    shape = body.default_shape()
    motion = procedural_motion('sway', body.joint_names, seconds=0.5, amplitude=0.0)
    settings = XPBDSettings(fps=motion.fps, substeps=100, iterations=1, backend='warp',
                            bend_every=10)
    largest = {}
    for spec in (ShippedGarmentSpec('shorts'), ShippedGarmentSpec('shorts', merge_edges_below=0.5)):
        shorts = fit_garment(spec, body, shape)
        result = simulate_sequence(body, shape, shorts, motion, settings).result
        assert torch.isfinite(result.positions).all()
        largest[shorts.name] = np.max(result.max_stretch)
    assert shorts.name == 'makehuman-shorts-m0.5'
    assert largest['makehuman-shorts'] > STRETCH_BAR > largest['makehuman-shorts-m0.5']
    surface = trimesh.Trimesh(shorts.mesh.vertices, shorts.mesh.faces, process=False)
    assert surface.euler_number == -1 and surface.is_winding_consistent  # a tube with two legs
    assert np.ptp(shorts.mesh.vertices[shorts.pinned, 2]) < 0.1  # the waistband
