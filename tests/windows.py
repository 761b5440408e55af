"""A tiny simulated dataset with its feature cache, shared by the estimator and
training tests (built once per test session, ~20 s)."""

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
