"""Write ``single_scatter_alu_pipe.npz``: the laser integrator's image before interreflections.

Run it from a checkout of the commit the reference is to record (it was made at 905e28a, the
integrator without ``max_scatter``)::

    PYTHONPATH=src python3 tests/simulator/data/make_single_scatter_reference.py

The image: the paper rig, ``alu-pipe``, ambient ``dim``, scale 0.125, 4 spp, seed 3, llvm_ad_mono.
"""

import subprocess
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

mi.set_variant("llvm_ad_mono")

from lts360.scenes.objects import build_object
from lts360.scenes.rig_io import load_rig
from lts360.simulator.render import render_radiance
from lts360.simulator.scene import SceneSpec, object_meshes

spec = SceneSpec(load_rig("paper"), object_meshes(build_object("alu-pipe")), ambient="dim")
res = render_radiance(spec, spp=4, seed=3, scale=0.125)
commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, check=True,
                        text=True).stdout.strip()
np.savez_compressed(Path(__file__).with_name("single_scatter_alu_pipe.npz"),
                    radiance=res.radiance_W_m2_sr, laser=res.laser_W_m2_sr, commit=commit,
                    mitsuba=mi.__version__, drjit=dr.__version__)
