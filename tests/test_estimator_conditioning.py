"""The estimator's conditioning paths: the spectral descriptor changes the output
(through the shape parser), and training reaches every parameter group, including
the shape parser, the body parser and the detail network."""

import copy

import torch
from torch_geometric.data import Batch

from swingar_pyg.models import SwinGarEstimator
from tests.windows import SMALL_ESTIMATOR


def randomised(**kwargs) -> SwinGarEstimator:
    """A float64 estimator whose zero-initialised heads are randomised: untrained, it
    is exactly rigid skinning, which no descriptor, body code or detail state changes."""
    model = SwinGarEstimator(**{**SMALL_ESTIMATOR, **kwargs})
    for head in (model.skinning_head, model.blend_head, model.correction):
        if head is not None:
            torch.nn.init.normal_(head.weight, std=0.05)
            torch.nn.init.normal_(head.bias, std=0.05)
    return model.double().eval()


def as_double(windows) -> Batch:
    batch = Batch.from_data_list(windows)
    return batch.apply(lambda x: x.double() if x.is_floating_point() else x)


def test_the_descriptor_changes_the_output(tiny_windows):
    """The same garment and motion with another garment's descriptor: both the skinned
    and the refined vertices move. In float64 any change above roundoff is the
    descriptor's; measured 42 um at most for a randomised (untrained) estimator,
    so 1 um is a bound that a descriptor the network ignores fails by far."""
    window = tiny_windows.datasets['train'][0]
    other = copy.copy(window)
    other.descriptor = tiny_windows.datasets['val'][0].descriptor
    assert not torch.equal(window.descriptor, other.descriptor)
    model = randomised()
    with torch.no_grad():
        a, b = model(as_double([window])), model(as_double([other]))
    for name in ('skinned', 'vertices'):
        change = (getattr(a, name) - getattr(b, name)).norm(dim=-1).max().item()
        assert change > 1e-6, (name, change)
    # the "no descriptor" ablation ignores it
    ablation = randomised(descriptor_size=None)
    with torch.no_grad():
        assert torch.equal(ablation(as_double([window])).vertices,
                           ablation(as_double([other])).vertices)


def test_every_parameter_receives_a_finite_nonzero_gradient(tiny_windows):
    """One training loss on two garments: every parameter of every group gets a
    finite gradient that is not zero, so none is cut off from the loss."""
    dataset = tiny_windows.datasets['train']
    batch = as_double([dataset[0], dataset[len(dataset) - 1]])
    model = randomised().train()
    out = model(batch)
    loss = (out.vertices - batch.target.transpose(0, 1)).square().sum(-1).mean()
    loss.backward()
    groups = {name.split('.')[0] for name, _ in model.named_parameters()}
    assert {'shape_parser', 'body_parser', 'detail', 'motion_encoder',
            'garment_encoder'} <= groups
    for name, parameter in model.named_parameters():
        assert parameter.grad is not None, name
        assert torch.isfinite(parameter.grad).all(), name
        assert parameter.grad.abs().max() > 0, name


def test_gradients_of_the_conditioning_paths_match_finite_differences(tiny_windows):
    """The shape parser, the body parser and the detail network, which the estimator's
    finite-difference test leaves out: the analytic gradient matches central
    differences (float64, step 1e-6: truncation and roundoff far below 1e-4 relative)."""
    batch = as_double([tiny_windows.datasets['val'][4]])
    model = randomised()
    names = ['shape_parser.0.weight', 'shape_parser.2.bias', 'body_parser.0.weight',
             'body_parser.2.weight', 'detail.input_maps.lin.weight',
             'detail.state_maps.att_src', 'detail.peephole']
    parameters = dict(model.named_parameters())

    def loss(values):
        return torch.func.functional_call(model, dict(zip(names, values)),
                                          (batch,)).vertices.square().sum()

    values = [parameters[name].detach().clone().requires_grad_() for name in names]
    analytic = torch.autograd.grad(loss(values), values)
    step = 1e-6
    generator = torch.Generator().manual_seed(0)
    for k, name in enumerate(names):
        # the entry with the largest gradient, and a random one
        largest = tuple(int(i) for i in torch.unravel_index(analytic[k].abs().argmax(),
                                                            values[k].shape))
        random = tuple(int(torch.randint(s, (), generator=generator)) for s in values[k].shape)
        for index in (largest, random):
            shifted = []
            for sign in (1, -1):
                moved = [v.detach().clone() for v in values]
                moved[k][index] += sign * step
                shifted.append(loss(moved))
            numeric = (shifted[0] - shifted[1]) / (2 * step)
            assert torch.isclose(analytic[k][index], numeric, rtol=1e-4, atol=1e-9), \
                (name, index, float(analytic[k][index]), float(numeric))
        assert analytic[k].abs().max() > 0, name
