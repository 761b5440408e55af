r"""The SwinGar estimator (paper §3.3, docs/design.md §4).

.. math::
    \mathbf{M}^t = W(\mathbf{M}^0, \boldsymbol\beta, \boldsymbol\theta^{t-m..t})

A garment graph :math:`G^0` with node features :math:`[\mathbf{n}_i, \mathbf{x}_i, a_i]`
passes through the garment encoder :math:`M_g` (FCA layers); its spectral
descriptor :math:`\boldsymbol\lambda` through the shape parser :math:`A_s` (MLP).
An LSTM :math:`M_m` encodes each target frame's pose window into a motion code,
the body parser :math:`A_b` maps body shape and current pose to a body code. Then

.. math::
    \mathbf{s} = E(M_g(G^0) \odot \mathbf{c}_m), \qquad
    (\mathbf{W}^t, \mathbf{B}^t) = P(\mathbf{s} \odot \mathbf{c}_s), \qquad
    \mathbf{M}_c^t = \mathrm{LBS}(\mathbf{M}^0 + \mathbf{B}^t, \boldsymbol\theta^t, \mathbf{W}^t),

with :math:`E` and :math:`P` stacks of FCA layers and :math:`\mathbf{W}^t` a softmax
over the body's joints. The detail network :math:`M_d`, an :class:`FCALSTM`, runs
over :math:`G^{t-2}, G^{t-1}, G^t` built on :math:`\mathbf{M}_c` with features
:math:`[\mathbf{x}, \lVert \mathbf{x} - \mathbf{j}_k \rVert_{k=1..J}]`, and

.. math::
    \mathbf{M}^t = \mathbf{M}_c^t
        + \mathbf{R}_c\, \mathrm{Linear}(\mathbf{h}^t \odot \mathbf{c}_b^t).

Beyond the paper: the skinning logits are added to :math:`\log` of the weights
transferred from the body (``skinning_prior``), and the last layers of both
heads and of the correction start at zero, so an untrained estimator is exactly
rigid skinning with transferred weights and training starts from that baseline.
With a ``clearance_scale`` :math:`d_0`, each learned term of vertex :math:`i`
(skinning logits, blend shape, correction) is scaled by a gate of its rest
clearance :math:`c_i` (the garment's ``fit``),

.. math::
    g_i = 1 - \exp\left(-\max(c_i - c_0, 0) / d_0\right),

so cloth lying on the body (no more than the ``contact_clearance`` :math:`c_0`
from it) is rigidly skinned whatever the network predicts, and the learned terms
fade in over the next :math:`d_0` of room. With an ``anchor_scale`` :math:`l_0` the gate
also fades the terms in with the cloth's distance along the mesh from where it
lies on the body (:mod:`~swingar_pyg.models.clearance_gate`), so cloth held by
close-fitting neighbours is faded towards rigid skinning too. The gate holds no parameters: it
can be set on an estimator trained without it (``swingar ship-weights
--clearance-scale --anchor-scale``), which guards the close-fitting cloth more
strictly than training with it, where the network learns to push against it.
Positions fed to :math:`M_d` and its correction are in the canonical frame
(:mod:`~swingar_pyg.models.pose_features`) of their own frame, so the correction
turns with the body and a frame's input to :math:`M_d` is the same in every window
that contains it (a stream computes it once, :class:`~swingar_pyg.inference.SwinGarStream`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch
from torch import Tensor, nn
from torch_geometric.utils import add_remaining_self_loops

from swingar_pyg.models.clearance_gate import clearance_gate
from swingar_pyg.models.pose_features import pose_feature_size
from swingar_pyg.models.pretrained import read_weights
from swingar_pyg.nn import FCALSTM, FCAStack, attention_edge_index

TARGET_FRAMES = 3
_PRIOR_FLOOR = 1e-6


@dataclass
class EstimatorOutput:
    """Predictions at the three target frames: ``vertices`` :math:`\\mathbf{M}`
    and ``skinned`` :math:`\\mathbf{M}_c`, both ``(3, N, 3)`` in world space, and
    the blend shapes :math:`\\mathbf{B}` ``(3, N, 3)`` in the rest frame."""

    vertices: Tensor
    skinned: Tensor
    blend: Tensor


def _mlp(in_channels: int, channels: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(in_channels, channels), nn.ELU(),
                         nn.Linear(channels, channels))


def skin_points(rest: Tensor, weights: Tensor, transforms: Tensor, batch: Tensor) -> Tensor:
    r"""Dense linear blend skinning of the points of ``G`` garments, each on its
    own posed body: :math:`\sum_j w_{ij} \mathbf{G}_{g(i),j} [\mathbf{x}_i; 1]`.

    The weights meet each body's transforms in one ``(N, J) @ (J, 12 G)`` product;
    per-point ``(N, J, 4, 4)`` transforms are never gathered.

    Args:
        rest: ``(N, 3)``; weights: ``(N, J)``; transforms: ``(G, J, 4, 4)``;
        batch: ``(N,)`` the garment of each point.
    """
    graphs, joints = transforms.shape[:2]
    rows = transforms[..., :3, :].permute(1, 0, 2, 3).reshape(joints, graphs * 12)
    blended = (weights @ rows).view(-1, graphs, 3, 4)
    blended = blended[torch.arange(len(batch), device=batch.device), batch]
    return (blended[..., :3] @ rest.unsqueeze(-1)).squeeze(-1) + blended[..., 3]


def descriptor_features(descriptor: Tensor) -> Tensor:
    """Maps eigenvalues of ``A / N`` (in ``[0, 1]``, spanning decades) to
    ``[0, 1]`` on a log scale: ``1 + log10(max(λ, 1e-6)) / 6``."""
    return 1.0 + torch.log10(descriptor.clamp_min(1e-6)) / 6.0


class SwinGarEstimator(nn.Module):
    r"""Predicts garment vertices at frames ``t-2, t-1, t`` from a
    :class:`~swingar_pyg.models.GarmentWindow` (or a Batch of them).

    Args:
        num_joints (int): joints of the body rig :math:`J`. (default: :obj:`31`)
        shape_size (int): body shape parameters. (default: :obj:`6`)
        channels (int): width of every hidden layer. (default: :obj:`64`)
        garment_layers (int): FCA layers of :math:`M_g`. (default: :obj:`2`)
        state_layers (int): FCA layers of :math:`E`. (default: :obj:`1`)
        predictor_layers (int): FCA layers of :math:`P`. (default: :obj:`2`)
        heads (int): attention heads per FCA layer, averaged. (default: :obj:`1`)
        alpha (float): FCA score bound. (default: :obj:`2.0`)
        normalize (bool): :obj:`False` turns every FCA layer into GAT (the
            "no FCA" ablation). (default: :obj:`True`)
        descriptor_size (int, optional): descriptor length ``z``; :obj:`None`
            drops the shape parser (the "no descriptor" ablation).
            (default: :obj:`256`)
        history (int): pose history ``m``. (default: :obj:`64`)
        skinning_prior (bool): start skinning from the transferred weights.
            (default: :obj:`True`)
        detail (bool): run :math:`M_d`; :obj:`False` returns :math:`\mathbf{M}_c`.
            (default: :obj:`True`)
        detail_channels (int): state size of :math:`M_d` and of the body code;
            its four gate heads make it the costliest layer per channel.
            (default: :obj:`32`)
        clearance_scale (float, optional): :math:`d_0` in metres, the rest
            clearance over which the learned terms fade in (needs the skinning
            prior); :obj:`None` leaves that factor out. (default: :obj:`None`)
        contact_clearance (float, optional): :math:`c_0` in metres, the rest
            clearance of cloth lying on the body, e.g. the dressing clearance
            of :func:`~swingar_pyg.world.garment.garment_on_body`.
            (default: :obj:`0.0`)
        anchor_scale (float, optional): :math:`l_0` in metres, the length of
            cloth from where the garment lies on the body over which the learned
            terms fade in (needs the skinning prior and a positive
            ``contact_clearance``); :obj:`None` leaves that factor out. Without
            either scale the learned terms apply everywhere. It is computed anew
            on every :meth:`forward`: set it on a trained network, for inference.
            (default: :obj:`None`)
    """

    def __init__(self, num_joints: int = 31, shape_size: int = 6, channels: int = 64,
                 garment_layers: int = 2, state_layers: int = 1, predictor_layers: int = 2,
                 heads: int = 1, alpha: float = 2.0, normalize: bool = True,
                 descriptor_size: int | None = 256, history: int = 64,
                 skinning_prior: bool = True, detail: bool = True,
                 detail_channels: int = 32, clearance_scale: float | None = None,
                 contact_clearance: float = 0.0, anchor_scale: float | None = None):
        super().__init__()
        if history < 1:
            raise ValueError(f"the pose history needs at least one frame, got {history}")
        for name, scale in (("clearance_scale", clearance_scale),
                            ("anchor_scale", anchor_scale)):
            if scale is None:
                continue
            if not 0.0 < scale < float("inf"):
                raise ValueError(f"{name} must be finite positive metres, got {scale}")
            if not skinning_prior:
                raise ValueError(f"{name} fades the learned terms into rigid skinning "
                                 "and needs skinning_prior=True")
        if not 0.0 <= contact_clearance < float("inf"):
            raise ValueError(f"contact_clearance must be finite metres >= 0, "
                             f"got {contact_clearance}")
        if anchor_scale is not None and contact_clearance == 0.0:
            raise ValueError("anchor_scale fades the terms in from cloth lying on the body and "
                             "needs its contact_clearance (e.g. 0.006, the dressing clearance "
                             "of garment_on_body): at 0 no dressed vertex lies on the body")
        self.num_joints = num_joints
        self.descriptor_size = descriptor_size
        self.history = history
        self.skinning_prior = skinning_prior
        self.clearance_scale = clearance_scale
        self.contact_clearance = contact_clearance
        self.anchor_scale = anchor_scale
        pose_size = pose_feature_size(num_joints)
        stack = dict(heads=heads, alpha=alpha, normalize=normalize, add_self_loops=False)
        self.garment_encoder = FCAStack(7, channels, garment_layers, **stack)
        self.shape_parser = (_mlp(descriptor_size, channels)
                             if descriptor_size is not None else None)
        self.motion_encoder = nn.LSTM(pose_size + 1, channels, batch_first=True)
        self.body_parser = _mlp(shape_size + pose_size, detail_channels)
        self.state_encoder = FCAStack(channels, channels, state_layers, **stack)
        self.predictor = FCAStack(channels, channels, predictor_layers, **stack)
        self.skinning_head = nn.Linear(channels, num_joints)
        self.blend_head = nn.Linear(channels, 3)
        self.detail = (FCALSTM(3 + num_joints, detail_channels, alpha=alpha,
                               normalize=normalize, add_self_loops=False) if detail else None)
        self.correction = nn.Linear(detail_channels, 3) if detail else None
        for head in (self.skinning_head, self.blend_head, self.correction):
            if head is not None:
                nn.init.zeros_(head.weight)
                nn.init.zeros_(head.bias)

    @classmethod
    def from_pretrained(cls, name_or_path: str | Path = "base") -> "SwinGarEstimator":
        """A trained estimator, in eval mode: the weights shipped with the package
        by name (``"base"``, see its model card ``swingar_pyg/weights/base.md``)
        or a ``.pt`` file of ``swingar ship-weights``. A new garment's descriptor
        must be computed with the settings in the file's ``data`` entry
        (:func:`~swingar_pyg.training.load_pretrained` returns them; ``swingar
        predict`` uses them)."""
        return cls.from_weights(read_weights(name_or_path))

    @classmethod
    def from_weights(cls, record: dict) -> "SwinGarEstimator":
        """The estimator of a weights record (:func:`~swingar_pyg.models.pretrained.read_weights`),
        in eval mode."""
        estimator = cls(**record["estimator"])
        estimator.load_state_dict(record["state_dict"])
        return estimator.eval()

    def encode_garment(self, data) -> tuple[Tensor, Tensor, Tensor]:
        """The motion-independent part: attention graph, :math:`M_g` features
        ``(N, C)`` and the shape code per vertex ``(N, C)``."""
        if torch.compiler.is_compiling():  # EdgeIndex does not trace: a plain tensor
            edge_index, _ = add_remaining_self_loops(data.edge_index, num_nodes=data.num_nodes)
        else:
            edge_index = attention_edge_index(data.edge_index, data.num_nodes)
        x = torch.cat([data.normal, data.rest, data.fit.unsqueeze(-1)], dim=-1)
        features = self.garment_encoder(x, edge_index)
        if self.shape_parser is None:
            shape_code = torch.ones_like(features)
        else:
            if data.descriptor.size(-1) != self.descriptor_size:
                raise ValueError(f"the estimator expects descriptors of length "
                                 f"{self.descriptor_size}, got {data.descriptor.size(-1)}")
            shape_code = self.shape_parser(descriptor_features(data.descriptor))[batch_vector(data)]
        return edge_index, features, shape_code

    def clearance_gate(self, fit: Tensor, edge_index: Tensor | None = None,
                       rest: Tensor | None = None) -> Tensor | None:
        """:math:`g` ``(N, 1)`` of the rest clearances ``fit`` ``(N,)``
        (:func:`~swingar_pyg.models.clearance_gate.clearance_gate`), or :obj:`None`
        without a ``clearance_scale`` or an ``anchor_scale``; the anchor factor
        needs the garment's mesh ``edge_index`` and ``rest`` positions."""
        return clearance_gate(fit, self.contact_clearance, self.clearance_scale,
                              self.anchor_scale, edge_index, rest)

    def motion_codes(self, pose_history: Tensor, history_mask: Tensor) -> Tensor:
        """:math:`M_m`: ``(G, F, m, P)`` windows and masks ``(G, F, m)`` → ``(G, F, C)``."""
        graphs, frames, length, size = pose_history.shape
        inputs = torch.cat([pose_history, history_mask.unsqueeze(-1)], dim=-1)
        # The LSTM runs in the weights' precision: under CPU autocast oneDNN has no
        # bfloat16 LSTM and fails, and a 64-step recurrence loses most in half precision.
        with torch.autocast(inputs.device.type, enabled=False):
            _, (h, _) = self.motion_encoder(inputs.reshape(graphs * frames, length, size + 1).to(
                self.motion_encoder.weight_ih_l0.dtype))
        return h[-1].reshape(graphs, frames, -1)

    def body_codes(self, body_shape: Tensor, pose_history: Tensor) -> Tensor:
        """:math:`A_b([\\beta, \\theta^k])` for every target frame: ``(G, F, C)``."""
        current = pose_history[:, :, -1]
        shape = body_shape.unsqueeze(1).expand(-1, current.size(1), -1)
        return self.body_parser(torch.cat([shape, current], dim=-1))

    def skinning_terms(self, data, edge_index: Tensor, garment_features: Tensor,
                       shape_code: Tensor, motion_code: Tensor,
                       gate: Tensor | None) -> tuple[Tensor, Tensor]:
        r"""The skinning weights :math:`\mathbf{W}` ``(N, J)`` and blend shapes
        :math:`\mathbf{B}` ``(N, 3)`` of one frame, given its motion code ``(G, C)``;
        the learned logits and blend shapes are scaled by the :meth:`clearance_gate`
        ``(N, 1)`` (none: :obj:`None`)."""
        state = self.state_encoder(garment_features * motion_code[batch_vector(data)], edge_index)
        hidden = self.predictor(state * shape_code, edge_index)
        logits, blend = self.skinning_head(hidden), self.blend_head(hidden)
        if gate is not None:
            logits, blend = gate * logits, gate * blend
        if self.skinning_prior:
            logits = logits + torch.log(data.prior_weights.clamp_min(_PRIOR_FLOOR))
        return torch.softmax(logits, dim=-1), blend

    def skin(self, data, edge_index: Tensor, garment_features: Tensor, shape_code: Tensor,
             motion_code: Tensor, transforms: Tensor, gate: Tensor | None) -> Tensor:
        r""":math:`\mathbf{M}_c` at one frame, given that frame's motion code
        ``(G, C)``, skinning transforms ``(G, J, 4, 4)`` and :meth:`clearance_gate`:
        ``(N, 3)``."""
        weights, blend = self.skinning_terms(data, edge_index, garment_features, shape_code,
                                             motion_code, gate)
        return skin_points(data.rest + blend, weights, transforms, batch_vector(data))

    def detail_inputs(self, skinned: Tensor, joint_positions: Tensor, frame_rotation: Tensor,
                      frame_origin: Tensor, batch: Tensor) -> Tensor:
        r"""The node features of :math:`M_d` at one frame, ``(N, 3 + J)``: the
        skinned positions ``(N, 3)`` in that frame's canonical frame
        (:math:`\mathbf{R}_c^\top (\mathbf{x} - \mathbf{p})`, per garment
        ``(G, 3, 3)`` and ``(G, 3)``) and their distances to the joints ``(G, J, 3)``.
        They depend on that frame alone, so a stream computes them once."""
        local = torch.einsum("nba,nb->na", frame_rotation[batch], skinned - frame_origin[batch])
        distances = (skinned.unsqueeze(1) - joint_positions[batch]).norm(dim=-1)
        return torch.cat([local, distances], dim=-1)

    def correct(self, skinned: Tensor, hidden: Tensor, body_code: Tensor,
                frame_rotation: Tensor, batch: Tensor, gate: Tensor | None) -> Tensor:
        r"""Adds :math:`\mathbf{R}_c\, \mathrm{Linear}(\mathbf{h} \odot
        \mathbf{c}_b)` to ``skinned`` ``(N, 3)`` at one frame, given the detail
        state ``(N, C)``, per garment the body code ``(G, C)``, the frame's
        canonical rotation ``(G, 3, 3)`` and the :meth:`clearance_gate` ``(N, 1)``."""
        correction = self.correction(hidden * body_code[batch])
        if gate is not None:
            correction = gate * correction
        return skinned + torch.einsum("nab,nb->na", frame_rotation[batch], correction)

    def refine(self, edge_index: Tensor, batch: Tensor, skinned: Tensor,
               joint_positions: Tensor, body_codes: Tensor, frame_rotation: Tensor,
               frame_origin: Tensor, gate: Tensor | None) -> Tensor:
        r""":math:`M_d`: adds the detail correction to ``skinned`` ``(F, N, 3)``,
        given per garment and frame the joint positions ``(G, F, J, 3)``, body
        codes ``(G, F, C)`` and canonical frames ``(G, F, 3, 3)``, ``(G, F, 3)``,
        and the :meth:`clearance_gate` ``(N, 1)``."""
        inputs = torch.stack([
            self.detail_inputs(skinned[k], joint_positions[:, k], frame_rotation[:, k],
                               frame_origin[:, k], batch) for k in range(len(skinned))])
        hidden, _ = self.detail(inputs, edge_index)
        return torch.stack([
            self.correct(skinned[k], hidden[k], body_codes[:, k], frame_rotation[:, k], batch,
                         gate) for k in range(len(skinned))])

    def forward(self, data) -> EstimatorOutput:
        _check_window(data, self.num_joints, self.history)
        edge_index, features, shape_code = self.encode_garment(data)
        motion = self.motion_codes(data.pose_history, data.history_mask)
        batch = batch_vector(data)
        gate = self.clearance_gate(data.fit, data.edge_index, data.rest)
        terms = [self.skinning_terms(data, edge_index, features, shape_code, motion[:, k], gate)
                 for k in range(TARGET_FRAMES)]
        blend = torch.stack([offsets for _, offsets in terms])
        skinned = torch.stack([
            skin_points(data.rest + blend[k], weights, data.joint_transforms[:, k], batch)
            for k, (weights, _) in enumerate(terms)])
        if self.detail is None:
            return EstimatorOutput(skinned, skinned, blend)
        codes = self.body_codes(data.body_shape, data.pose_history)
        vertices = self.refine(edge_index, batch, skinned, data.joint_positions, codes,
                               data.frame_rotation, data.frame_origin, gate)
        return EstimatorOutput(vertices, skinned, blend)


def batch_vector(data) -> Tensor:
    batch = getattr(data, "batch", None)
    if batch is None:
        batch = data.rest.new_zeros(data.num_nodes, dtype=torch.long)
    return batch


def _check_window(data, num_joints: int, history: int) -> None:
    expected = {"rest": (3,), "normal": (3,), "fit": (), "prior_weights": (num_joints,)}
    for name, tail in expected.items():
        value = getattr(data, name, None)
        if value is None or tuple(value.shape[1:]) != tail:
            got = None if value is None else tuple(value.shape)
            shape = f"(N, {', '.join(map(str, tail))})" if tail else "(N,)"
            raise ValueError(f"data.{name} must have shape {shape}, got {got}")
    windows = data.pose_history.shape
    if windows[1:3] != (TARGET_FRAMES, history):
        raise ValueError(f"data.pose_history must hold {TARGET_FRAMES} windows of {history} "
                         f"frames, got shape {tuple(windows)}")
    if not torch.isfinite(data.rest).all():
        raise ValueError("the garment's rest vertices are not finite")
    if not torch.isfinite(data.fit).all():
        raise ValueError("the garment's rest clearances (data.fit) are not finite")
