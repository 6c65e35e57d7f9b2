#!/usr/bin/env bash
# GPU check of lts360: render rate (cuda_ad_mono), recon kernel (Dr.Jit CUDA) and the wall time of
# a 1000-trial Monte Carlo, printed as one table with the targets beside (≤ 8 min in all).
# What is measured, and how: the docstring of benchmarks/gpu_check.py.
#
# Beforehand, on a machine with a package index, in the repository root (Python 3.12 wheels,
# manylinux x86-64, into .whl/, which git ignores; carry .whl/ to the GPU machine):
#
#   bash ../shared/tools/gpu-wheels.sh numpy==2.4.6 scipy==1.17.1 trimesh==5.2.0 \
#       manifold3d==3.5.4 OpenEXR==3.5.3 opencv-python-headless==5.1.0.95 xarray==2026.9.0 \
#       pandas==3.1.1 python-dateutil==2.9.0.post0 six==1.17.0 packaging==26.2 tqdm==4.70.1
#
# These extras are what the check imports (lts360 and the hard requirements of its imports):
# numpy, scipy, trimesh; manifold3d (the object catalog imports every generator); OpenEXR and
# opencv-python-headless (the Monte Carlo placements are written as EXR + PNG); xarray, pandas,
# python-dateutil, six, packaging, tqdm (lts360.experiments.runner, imported by the Monte Carlo
# trial).  Leave out any the GPU machine already has: the check names what is missing in one
# line.  The versions are those the test suite passes with; other numpy 2 / pandas ≥ 2.2 builds
# do as well.  The wheels script keeps only Mitsuba's scalar and CUDA variants (no llvm_ad_*),
# so --variant llvm_ad_mono does not exist there; the LLVM reference of the recon kernel needs
# a libLLVM on that machine (else its row says FAILED and the numpy reference row remains).
#
# Usage (repository root):   bash benchmarks/gpu_check.sh [--quick] [--json OUT] [...]
# Arguments go to benchmarks/gpu_check.py (--variant, --backend, --quick, --workers,
# --mc-deadline, --json).  Without CUDA:  bash benchmarks/gpu_check.sh --variant llvm_ad_mono
# --backend llvm --quick
set -uo pipefail
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
timeout 450 python3 benchmarks/gpu_check.py "$@"
status=$?
[ "$status" -eq 124 ] && echo "gpu_check.py stopped after 450 s (the 8-minute budget)"
exit "$status"
