#!/usr/bin/env bash
# Install lts360 and everything it needs on a Debian/Ubuntu machine (run as root or with sudo).
#  - libllvm19: Mitsuba's CPU (LLVM) variants crash with Debian's default LLVM 14/15
#    ("LLVM ERROR: Cannot select ... fminimum"); Dr.Jit finds LLVM 19 by itself.
#  - libusb-1.0-0: needed by Open3D (point-to-mesh distances in scoring).
#  - the Python package with its test extras, editable, into the current Python.
set -euo pipefail
cd "$(dirname "$0")/.."
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
if command -v apt-get >/dev/null 2>&1; then
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libllvm19 libusb-1.0-0 >/dev/null
else
  echo "install.sh: no apt-get; install LLVM >= 16 (libLLVM.so) yourself and set DRJIT_LIBLLVM_PATH" >&2
fi
python3 -m pip install -q --upgrade pip >/dev/null 2>&1 || true
python3 -m pip install -q -e ".[test]"
python3 -c "import mitsuba as mi; mi.set_variant('llvm_ad_mono'); print('mitsuba', mi.__version__, 'llvm_ad_mono ok')"
