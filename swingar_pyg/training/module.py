"""The Lightning experiment: losses, metrics and optimisation around a
:class:`~swingar_pyg.models.SwinGarEstimator` (which holds the math)."""

from __future__ import annotations

import lightning as L
import torch

from swingar_pyg.models import EstimatorOutput, SwinGarEstimator, losses
from swingar_pyg.models.estimator import TARGET_FRAMES
from swingar_pyg.training.network_hyperparameters import save_hyperparameters_with_network
from swingar_pyg.training.vertex_errors import VertexErrors


class SwinGarModule(L.LightningModule):
    r"""Trains a :class:`SwinGarEstimator` on :class:`GarmentWindow` batches.

    Logs every loss term (``train/loss_vertex``, ...) and, for validation and
    test, per-vertex error at the newest frame ``t`` in millimetres (mean, RMSE,
    p95) of the estimator and of rigid skinning, over the split and per garment
    family; :attr:`last_summary` keeps the full per-garment and per-motion
    table of the last validation or test epoch.

    Args:
        estimator: the network.
        vertex_weight, edge_weight, bending_weight, velocity_weight,
            collision_weight: loss weights of the prediction (0 skips a term).
        skinned_weight: weight of a vertex loss on the skinned garment
            :math:`\mathbf{M}_c` before the detail correction (deep supervision;
            off by default: on quickstart it made validation worse, 16.7 against
            14.6 mm).
        blend_weight, correction_weight: weights of an offset loss on the blend
            shapes :math:`\mathbf{B}` and on the detail correction
            :math:`\mathbf{M} - \mathbf{M}_c` (0 skips it).
        collision_margin: distance (m) the collision loss keeps from the body.
        lr: Adam learning rate, annealed by a cosine over the run.
        weight_decay: AdamW weight decay.
        compile: run the estimator through :func:`torch.compile`.
    """

    def __init__(self, estimator: SwinGarEstimator, vertex_weight: float = 1.0,
                 edge_weight: float = 1.0, bending_weight: float = 1.0,
                 velocity_weight: float = 1.0, collision_weight: float = 0.1,
                 skinned_weight: float = 0.0, blend_weight: float = 0.0,
                 correction_weight: float = 0.0,
                 collision_margin: float = 0.004, lr: float = 1e-3,
                 weight_decay: float = 0.0, compile: bool = False):
        super().__init__()
        if correction_weight and estimator.detail is None:
            raise ValueError("correction_weight needs the detail network; the estimator was "
                             "built with detail=False")
        save_hyperparameters_with_network(self, "estimator")
        self.estimator = estimator
        self._network = torch.compile(estimator) if compile else estimator
        self.weights = {"vertex": vertex_weight, "edge": edge_weight,
                        "bending": bending_weight, "velocity": velocity_weight,
                        "collision": collision_weight, "skinned": skinned_weight,
                        "blend": blend_weight, "correction": correction_weight}
        self.errors = VertexErrors()
        self.last_summary: dict = {}

    def forward(self, batch):
        return self._network(batch)

    def _losses(self, batch, output: EstimatorOutput) -> dict[str, torch.Tensor]:
        prediction = output.vertices
        target = batch.target.transpose(0, 1)
        terms = {}
        if self.weights["skinned"]:
            terms["skinned"] = losses.vertex_loss(output.skinned, target)
        if self.weights["blend"]:
            terms["blend"] = losses.offset_loss(output.blend)
        if self.weights["correction"]:
            terms["correction"] = losses.offset_loss(prediction - output.skinned)
        if self.weights["vertex"]:
            terms["vertex"] = losses.vertex_loss(prediction, target)
        if self.weights["edge"]:
            terms["edge"] = losses.edge_length_loss(prediction, target, batch.edge_index)
        if self.weights["bending"]:
            terms["bending"] = losses.bending_loss(prediction, target, batch.edge_index)
        if self.weights["velocity"]:
            terms["velocity"] = losses.velocity_loss(prediction, target)
        if self.weights["collision"]:
            terms["collision"] = sum(
                losses.collision_loss(prediction[k], batch.batch, *losses.pose_body_points(
                    batch.body_points, batch.body_normals, batch.body_skin_indices,
                    batch.body_skin_weights, batch.joint_transforms[:, k]),
                    margin=self.hparams.collision_margin)
                for k in range(TARGET_FRAMES)) / TARGET_FRAMES
        return terms

    def _step(self, batch, stage: str) -> torch.Tensor:
        output = self(batch)
        prediction = output.vertices
        terms = self._losses(batch, output)
        loss = sum(self.weights[name] * value for name, value in terms.items())
        size = batch.num_graphs
        self.log(f"{stage}/loss", loss, batch_size=size, prog_bar=stage == "train")
        for name, value in terms.items():
            self.log(f"{stage}/loss_{name}", value, batch_size=size)
        if stage != "train":
            newest = batch.target[:, -1]
            for method, vertices in (("estimator", prediction[-1]),
                                     ("rigid", batch.rigid[:, -1])):
                errors = 1e3 * (vertices - newest).norm(dim=-1)
                self.errors.add(method, errors, batch.batch, list(batch.garment),
                                list(batch.motion))
        return loss

    def training_step(self, batch, batch_index: int) -> torch.Tensor:
        return self._step(batch, "train")

    def validation_step(self, batch, batch_index: int) -> None:
        self._step(batch, "val")

    def test_step(self, batch, batch_index: int) -> None:
        self._step(batch, "test")

    def predict_step(self, batch, batch_index: int):
        return self(batch).vertices.transpose(0, 1)

    def _summarise(self, stage: str) -> None:
        if not self.errors:
            return
        self.last_summary = self.errors.summary()
        self.errors = VertexErrors()
        for method in ("estimator", "rigid"):
            for key, value in self.last_summary[method]["all"].items():
                self.log(f"{stage}/{method}_{key}", value, sync_dist=True)
            for group, stats in self.last_summary[method].items():
                if group.startswith("family:"):
                    family = group.split(":", 1)[1]
                    self.log(f"{stage}/{family}/{method}_mean_mm", stats["mean_mm"],
                             sync_dist=True)

    def on_validation_epoch_end(self) -> None:
        self._summarise("val")

    def on_test_epoch_end(self) -> None:
        self._summarise("test")

    def configure_optimizers(self):
        optimizer = torch.optim.AdamW(self.parameters(), lr=self.hparams.lr,
                                      weight_decay=self.hparams.weight_decay)
        steps = max(int(self.trainer.estimated_stepping_batches), 1)
        schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, steps)
        return {"optimizer": optimizer,
                "lr_scheduler": {"scheduler": schedule, "interval": "step"}}
