#!/usr/bin/env bash
# GPU check of lts360: render rate (cuda_ad_mono; the full frame and the pixel support on a scene
# built once), recon kernel (Dr.Jit CUDA) and the wall time of a 1000-trial Monte Carlo, printed
# as one table with the targets beside (≤ 8 min in all).
# What is measured, and how: the docstring of benchmarks/gpu_check.py.
#
# Beforehand, on a machine with a package index, in the repository root (CPython 3.12 wheels,
# manylinux x86-64, into .whl/, which git ignores; .whl/ then travels with the tree):
#
#   bash ../shared/tools/gpu-wheels.sh trimesh==5.2.0 manifold3d==3.5.4 OpenEXR==3.5.3
#
# That is for the lent H200 image, whose python3 (3.12) already holds numpy, scipy, pandas,
# xarray, python-dateutil, six, packaging, tqdm and opencv-python-headless, and lacks trimesh,
# manifold3d and OpenEXR.  Mitsuba + Dr.Jit + these three are ~58 MB (55.6 MiB) of the 64 MiB
# that may travel with the working tree.  On a machine with none of them, the whole list of
# what the check imports is (lts360 plus the hard requirements of its imports; ~187 MB):
#
#   bash ../shared/tools/gpu-wheels.sh numpy==2.4.6 scipy==1.17.1 trimesh==5.2.0 \
#       manifold3d==3.5.4 OpenEXR==3.5.3 opencv-python-headless==5.1.0.95 xarray==2026.9.0 \
#       pandas==3.1.1 python-dateutil==2.9.0.post0 six==1.17.0 packaging==26.2 tqdm==4.70.1
#
# Why each: numpy, scipy, trimesh (everywhere); manifold3d (the object catalog imports every
# generator); OpenEXR and opencv-python-headless (the Monte Carlo placements are written as
# EXR + PNG); xarray (+ pandas, python-dateutil, six, packaging) and tqdm (imported by
# lts360.experiments.runner, which the Monte Carlo trial imports).  The versions are those the
# test suite passes with (this set was installed with --no-deps into a bare Python 3.12 and ran
# the recon and Monte Carlo parts).  The check names whatever is missing in one line; a part
# that cannot import its modules gets a FAILED row and the others still run.
# gpu-wheels.sh keeps only Mitsuba's scalar and CUDA variants (no llvm_ad_*: mi.variants()
# still lists them, but --variant llvm_ad_mono fails there); the LLVM reference of the recon
# kernel needs a libLLVM on that machine (without one its row says FAILED and the numpy
# reference row remains).  In a git worktree (.git is a file) gpu-wheels.sh stops at its
# "mkdir -p .git/info": run it in a main checkout, or copy .whl/ over.
#
# Usage (repository root):   bash benchmarks/gpu_check.sh [--quick] [--json OUT] [...]
# Arguments go to benchmarks/gpu_check.py (--variant, --backend, --quick, --workers,
# --mc-deadline, --json).  Without CUDA:  bash benchmarks/gpu_check.sh --variant llvm_ad_mono
# --backend llvm --quick.  Through the device tool: command
# "bash benchmarks/gpu_check.sh --json $OUT/gpu_check.json", carry [".whl"], timeout_s 540.
set -uo pipefail
export PYTHONUNBUFFERED=1
cd "$(dirname "$0")/.." || exit 1
if compgen -G ".whl/*.whl" > /dev/null; then
  python3 -m pip install -q --no-index --no-deps --no-compile --upgrade --target "$HOME/site" \
    .whl/*.whl || echo "pip install of .whl/ failed; using what is installed"
  export PYTHONPATH="$HOME/site:$PWD/src${PYTHONPATH:+:$PYTHONPATH}"
else
  export PYTHONPATH="$PWD/src${PYTHONPATH:+:$PYTHONPATH}"
fi
command -v nvidia-smi > /dev/null && nvidia-smi --query-gpu=name,driver_version,memory.total \
  --format=csv,noheader
python3 --version
timeout -k 10 420 python3 benchmarks/gpu_check.py "$@"
status=$?
[ "$status" -eq 124 ] && echo "gpu_check.py stopped after 420 s (the 8-minute budget)"
exit "$status"
