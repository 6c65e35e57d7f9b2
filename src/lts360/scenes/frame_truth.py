"""The ground truth of a rendered frame or scan folder: its object (rebuilt from the spec in
``frame.json``, or from the part's copy in the folder) and the stage position of each frame."""

from __future__ import annotations

from lts360.folders import frame_dirs, read_frame_meta
from lts360.scenes.objects.base import SceneObject
from lts360.scenes.objects.catalog import object_from_truth

__all__ = ["load_truth"]


def load_truth(truth_dir) -> tuple[SceneObject, list[float]]:
    """``(object, [z_mm …])`` of a frame folder or a scan folder.

    Raises
    ------
    ValueError
        Neither a frame nor a scan folder, or frames of different objects.
    """
    dirs = frame_dirs(truth_dir, "--truth")
    frames = [read_frame_meta(d) for d in dirs]
    specs = {f["object"]["spec"] for f in frames}
    if len(specs) != 1:
        raise ValueError(f"--truth: the frames hold different objects: {sorted(specs)}")
    return (object_from_truth(frames[0]["object"], dirs[0]),
            [float(f["stage"]["z_mm"]) for f in frames])
