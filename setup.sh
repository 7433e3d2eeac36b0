#!/usr/bin/env bash
# One command that sets csmlab up on a fresh machine: a virtual environment in .venv with csmlab
# and its test tools, and Debian's chromium for the browser test of the HTML report.
set -euo pipefail
cd "$(dirname "$0")"
python3 -m venv .venv
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -e ".[test,gl]"
# Debian packages: chromium + chromedriver drive the browser test of the HTML report; EGL/Mesa let
# VTK (PyVista) render the report's 3D view off-screen with no display, and give the GL oracle
# (tests/test_gl_oracle.py, moderngl) its headless OpenGL 4.5 on llvmpipe.
apt_packages="chromium chromium-driver libegl1 libegl-mesa0 libgl1-mesa-dri"
if ! command -v chromium >/dev/null 2>&1 || ! command -v chromedriver >/dev/null 2>&1 \
    || ! ldconfig -p | grep 'libEGL.so.1' >/dev/null; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $apt_packages >/dev/null
  else
    echo "setup: not root, cannot install $apt_packages: the browser test of the report will be skipped" >&2
  fi
fi
# Warp compiles a kernel module on its first launch and caches it: compiled here, once, so that the
# first `csmlab run` loads every kernel instead of compiling them inside the run (csmlab.kernels.cache).
echo "setup: compiling csmlab's Warp kernels into Warp's kernel cache (a minute or two, once)"
.venv/bin/python -c "from csmlab.kernels.cache import build_kernel_cache; build_kernel_cache()" >/dev/null
echo "csmlab is set up: run '.venv/bin/csmlab run'"
