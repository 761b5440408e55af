"""Every motion source behind one name: procedural families, the shipped CMU clips,
or a user's BVH file (retargeted onto the body by joint names)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import torch

from swingar_pyg.world.body import BodyModel
from swingar_pyg.world.bvh import read_bvh
from swingar_pyg.world.motion import (
    EXTREME_MOTIONS,
    PROCEDURAL_MOTIONS,
    Motion,
    arms_out,
    ease_from_rest,
    mirror_motion,
    procedural_motion,
)
from swingar_pyg.world.retarget import retarget


def shipped_clips() -> list[str]:
    """Names of the CMU clips shipped with the package (mocap.cs.cmu.edu)."""
    folder = resources.files("swingar_pyg.world") / "data" / "motions"
    return sorted(p.name[:-4] for p in folder.iterdir() if p.name.endswith(".bvh"))


def make_motion(source: str, body: BodyModel, shape: torch.Tensor, seconds: float | None = None,
                fps: float = 30.0, speed: float = 1.0, amplitude: float = 1.0,
                mirror: bool = False, joint_map: dict[str, str] | None = None,
                arms_out_degrees: float = 0.0) -> Motion:
    """A motion for ``body`` from ``source``: a procedural family (see
    :data:`~swingar_pyg.world.motion.PROCEDURAL_MOTIONS`, or a stress case of
    :data:`~swingar_pyg.world.motion.EXTREME_MOTIONS`), a shipped clip name
    (:func:`shipped_clips`), or a path to a ``.bvh`` file.

    A clip's frame 0 is its reference pose (a T-pose for CMU), not motion: it is
    dropped, and the clip is eased into from the body's rest pose over 0.5 s (see
    :func:`~swingar_pyg.world.motion.ease_from_rest`); the result is cut to
    ``seconds`` (all of it if ``None`` or longer). ``speed`` plays it faster or
    slower; ``amplitude`` applies to procedural motions only, ``arms_out_degrees`` to
    clips only (their upper arms turned away from the body before the ease from rest:
    :func:`~swingar_pyg.world.motion.arms_out`). ``joint_map`` names clip joints
    for the body (:func:`~swingar_pyg.world.retarget.retarget`; e.g.
    :data:`~swingar_pyg.world.smpl_body.CMU_TO_SMPL`).
    """
    if source in PROCEDURAL_MOTIONS + EXTREME_MOTIONS:
        if arms_out_degrees:
            raise ValueError("arms_out_degrees applies to captured clips; procedural motions "
                             "keep the arms clear of the body")
        return procedural_motion(source, body.joint_names, seconds=seconds or 4.0, fps=fps,
                                 amplitude=amplitude, speed=speed, mirror=mirror)
    if amplitude != 1.0:
        raise ValueError("amplitude applies to procedural motions, not to captured clips")
    if speed <= 0:
        raise ValueError(f"speed must be positive, got {speed}")
    if source in shipped_clips():
        resource = resources.files("swingar_pyg.world") / "data" / "motions" / f"{source}.bvh"
        with resources.as_file(resource) as path:
            clip = read_bvh(path)
    elif source.endswith(".bvh"):
        if not Path(source).is_file():
            raise ValueError(f"no BVH file at {source}")
        clip = read_bvh(source)
    else:
        raise ValueError(f"unknown motion {source!r}: use a procedural family "
                         f"({', '.join(PROCEDURAL_MOTIONS)}), a shipped clip "
                         f"({', '.join(shipped_clips())}) or a .bvh path")
    # Playing at `speed` is sampling the clip at fps / speed and calling it fps.
    motion = retarget(clip, body, shape, fps=fps / speed, joint_map=joint_map,
                      name=Path(source).stem)
    motion = arms_out(Motion(f"{motion.name}-s{speed:.2f}", motion.rotations[1:],
                             motion.translation[1:], fps, motion.joint_names), arms_out_degrees)
    motion = ease_from_rest(motion)
    if seconds is not None:
        frames = max(2, round(seconds * fps))
        motion = Motion(motion.name, motion.rotations[:frames], motion.translation[:frames], fps,
                        motion.joint_names)
    return mirror_motion(motion) if mirror else motion
