#!/usr/bin/env bash
# One command that sets csmlab up on a fresh machine: a virtual environment in .venv with csmlab
# and its test tools, and Debian's chromium for the browser test of the HTML report.
set -euo pipefail
cd "$(dirname "$0")"
python3 -m venv .venv
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -e ".[test]"
if ! command -v chromium >/dev/null 2>&1; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver libegl1 libegl-mesa0 libgl1-mesa-dri >/dev/null
  else
    echo "setup: chromium not found and not root: the browser test of the report will be skipped" >&2
  fi
fi
.venv/bin/python -c "import warp; warp.init()" >/dev/null
echo "csmlab is set up: run '.venv/bin/csmlab run'"
