import json

import numpy as np
import pytest
import torch

from tests.extras import require

require('anny')
require('lightning')


@pytest.fixture(scope='module')
def checkpoint(tiny_checkpoint):
    return tiny_checkpoint


def test_predict_animates_a_garment_of_unseen_topology_from_an_obj(checkpoint, tmp_path):
    from swingar_pyg.cli import main
    from swingar_pyg.inference.prediction import write_obj
    from swingar_pyg.world.body import AnnyBody
    from swingar_pyg.world.skirt import SkirtSpec, fit_procedural_skirt

    body = AnnyBody()
    shape = body.default_shape()
    # a resolution and triangulation the tiny dataset never had
    skirt = fit_procedural_skirt(SkirtSpec(length=0.7, flare=0.5, vertices=333, jitter=0.35,
                                           seed=9), body, shape)
    write_obj(tmp_path / 'mine.obj', skirt.mesh.vertices, skirt.mesh.faces)
    out = tmp_path / 'out'
    assert main(['predict', '--ckpt', str(checkpoint), '--garment', str(tmp_path / 'mine.obj'),
                 '--motion', 'kick', '--seconds', '0.5', '--out', str(out)]) == 0
    saved = np.load(out / 'garment.npz')
    vertices = saved['vertices']
    assert vertices.shape == (15, skirt.mesh.num_vertices, 3) and np.isfinite(vertices).all()
    assert len(list((out / 'frames').glob('*.obj'))) == 15 and (out / 'preview.gif').exists()
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['vertices'] == skirt.mesh.num_vertices
    assert summary['clearance_gate'] is None  # the tiny network was trained without one
    counts = summary['collisions']
    assert counts['inside_after'] <= counts['inside_before']
    assert counts['inside_after'] <= 0.005 * counts['vertex_frames']
    # near the body: no vertex farther from the posed body than 3 cm beyond where it
    # stands off the rest body (a flared hem stands up to 46 cm off the legs). Each
    # vertex moves with the body it is skinned to, so its distance to the body changes
    # only as the limbs move relative to each other: measured at most 12 mm farther
    # (the kicking leg mostly comes closer). It was the farthest vertex within 10 cm of
    # the farthest rest distance, which a garment sliding several cm off passed.
    from swingar_pyg.world.motion_library import make_motion

    clip = make_motion('kick', body, shape, seconds=0.5)
    posed = body.pose(shape, clip.rotations, clip.translation).vertices
    nearest = torch.cdist(torch.as_tensor(vertices), posed).min(dim=-1).values
    rest = torch.as_tensor(skirt.mesh.vertices, dtype=posed.dtype)
    at_rest = torch.cdist(rest, body.rest_vertices(shape).to(posed.dtype)).min(dim=-1).values
    assert float((nearest - at_rest).max()) < 0.03


def test_predict_finds_collisions_with_the_neural_body_sdf(checkpoint, tiny_body_sdf, tmp_path,
                                                           capsys):
    from swingar_pyg.cli import main

    out = tmp_path / 'out'
    assert main(['predict', '--ckpt', str(checkpoint), '--garment', 'dress_skirt_knee',
                 '--motion', 'kick', '--seconds', '0.3', '--body-sdf', str(tiny_body_sdf),
                 '--no-preview', '--out', str(out)]) == 0
    assert 'collisions (neural SDF' in capsys.readouterr().out
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['collisions']['sdf'] == 'neural'
    assert np.isfinite(np.load(out / 'garment.npz')['vertices']).all()
    with pytest.raises(SystemExit):
        main(['predict', '--ckpt', str(checkpoint), '--garment', 'dress_skirt_knee',
              '--body-sdf', str(tmp_path / 'none.ckpt'), '--out', str(out)])
    assert 'no body SDF checkpoint at' in capsys.readouterr().err


def test_predict_names_a_missing_garment_or_checkpoint(checkpoint, tmp_path, capsys):
    from swingar_pyg.cli import main

    with pytest.raises(SystemExit):
        main(['predict', '--ckpt', str(checkpoint), '--garment', 'no_such_dress',
              '--out', str(tmp_path)])
    assert 'neither a file nor a shipped garment' in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(['predict', '--ckpt', str(tmp_path / 'none.ckpt'), '--garment', 'tshirt_loose',
              '--out', str(tmp_path)])
    assert 'no checkpoint at' in capsys.readouterr().err
