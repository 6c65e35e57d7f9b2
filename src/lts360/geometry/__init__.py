"""Projective geometry shared by the simulator and the reconstruction.

Pinhole projection with Brown distortion (:mod:`.camera`), planar mirrors and the mirror
matrix ``T_pi`` of paper Eq. 3 (:mod:`.mirror`), least-squares fits (:mod:`.fit`).
Depends on numpy and scipy only.
"""

from lts360.geometry.camera import (
    backproject_pixels,
    camera_center,
    distort_normalized,
    look_at,
    project_camera_points,
    project_points,
    scale_intrinsics,
    undistort_normalized,
    world_to_camera,
)
from lts360.geometry.fit import CircleFit, PlaneFit, fit_circle, fit_plane
from lts360.geometry.mirror import (
    mirror_matrix,
    reflect_directions,
    reflect_points,
    reflect_pose,
    reflect_rays,
    transform_plane,
)

__all__ = [
    "backproject_pixels", "camera_center", "distort_normalized", "look_at",
    "project_camera_points", "project_points", "scale_intrinsics", "undistort_normalized", "world_to_camera",
    "CircleFit", "PlaneFit", "fit_circle", "fit_plane",
    "mirror_matrix", "reflect_directions", "reflect_points", "reflect_pose", "reflect_rays",
    "transform_plane",
]
