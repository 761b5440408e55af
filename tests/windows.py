"""A tiny simulated dataset with its feature cache, shared by the estimator and
training tests (built once per test session, ~20 s), and a tiny body SDF config."""

from pathlib import Path

TINY_WINDOWS = """
name: tiny-windows
output: {output}
seconds: 0.4
fps: 30
solver: {{substeps: 10, iterations: 2, settle_frames: 10}}
body_shapes: [[0.5, 0.5, 0.5, 0.5, 0.5, 0.5]]
splits:
  train:
    garments:
      - {{length: 0.4, flare: 0.3, vertices: 120}}
      - {{length: 0.5, vertices: 160, jitter: 0.3}}
    motions: [{{kind: walk}}]
  val:
    garments: [{{length: 0.45, flare: 0.2, vertices: 140, jitter: 0.3, seed: 5}}]
    motions: [{{kind: jump}}]
  test:
    garments: [{{length: 0.6, flare: 0.4, vertices: 130}}]
    motions: [{{kind: twist}}]
"""

SMALL_FEATURES = dict(descriptor_size=16, history=8, body_points=64)
SMALL_ESTIMATOR = dict(channels=16, detail_channels=8, descriptor_size=16, history=8)


def write_tiny_config(directory: Path) -> Path:
    path = directory / 'tiny-windows.yaml'
    path.write_text(TINY_WINDOWS.format(output=directory / 'data'))
    return path


TINY_BODY_SDF = """
trainer:
  max_steps: 4
  val_check_interval: 2
  log_every_n_steps: 1
  enable_progress_bar: false
  enable_model_summary: false
  default_root_dir: {root}
model:
  init_args:
    body_sdf: {{init_args: {{channels: 16, layers: 2, frequencies: 1}}}}
data:
  init_args:
    root: {root}/data
    workers: 1
    frames_per_batch: 2
    points_per_frame: 64
    samples:
      shapes: [[0.5, 0.5, 0.5, 0.5, 0.5, 0.5]]
      random_shapes: 1
      val_shapes: 1
      motions: [sway]
      val_motions: [leg_split]
      frames_per_motion: 1
      seconds: 1.0
      points_per_frame: 128
      garment_datasets: [{dataset}]
      garment_frames: 2
"""
