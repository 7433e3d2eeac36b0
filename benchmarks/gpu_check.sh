#!/usr/bin/env bash
# The GPU check (issue 44): the CUDA test subset and the GPU benchmarks, in under 8 minutes on a bare
# GPU machine, their output under $OUT (default ./gpu_check_out) for docs/performance.md.
#
#   bash benchmarks/gpu_check.sh pack      # here, where pip reaches PyPI: the wheels a GPU machine lacks
#   bash benchmarks/gpu_check.sh           # there: install them (once all parts arrived), test, benchmark
#   bash benchmarks/gpu_check.sh engines   # there, a later call: experiments/engines.toml --frames 12 on CUDA
#
# What a bare GPU machine lacks. This workplace's GPU image has Python 3.12 with NumPy, SciPy,
# scikit-image, Matplotlib, Jinja2, Typer, Rich, Pillow, PyYAML, pytest and pytest-xdist, but not
# warp-lang, colour-science or flip-evaluator, and it cannot reach a registry. `pack` downloads their
# wheels for CPython 3.12 (the versions this project's environment runs, read from $PYTHON), unpacks
# them into one site-packages tree, compresses it (xz) and cuts it into parts of at most $PART_SIZE (56M)
# under .whl/p0, .whl/p1, … (.whl/ is git-ignored): warp-lang's wheel alone is 149 MB, over the 64 MiB
# a device call may carry, so the tree travels in two or three calls, one part each, made back to back
# (the machine is given back ~30 s after a call, and with it the parts received):
#
#   run(carry=[".whl/p0"], command="bash benchmarks/gpu_check.sh", timeout_s=60)    # keeps part 0
#   run(carry=[".whl/p1"], command="bash benchmarks/gpu_check.sh", timeout_s=560)   # … the last part: the check
#
# A call that does not complete the set keeps its part in /tmp/csmlab-wheels and exits 3, naming the
# part to carry next; the call that completes it checks the whole against the manifest's SHA-256,
# unpacks it into /tmp/csmlab-site and runs the check. Where warp imports already (a machine that has
# it), nothing is unpacked.
#
# The check: the GPU named (nvidia-smi); the CUDA tests (every test module with a test taking the
# `device` fixture, the tests whose id names cuda: kernels on cuda:0, CPU = CUDA bit for bit, the tiled
# rasterizer on CUDA against the CPU walk); bench_frame on CUDA with the tiled rasterizer and with the
# walk; the default experiment on CUDA (--jobs 8) with its wall time. Each step has its own time limit
# and a failure does not stop the others; the exit status is the first failure's.
set -u -o pipefail
cd "$(dirname "$0")/.."

PYTHON=${PYTHON:-python3}
OUT=${OUT:-$PWD/gpu_check_out}
PART_SIZE=${PART_SIZE:-56M}
STORE=/tmp/csmlab-wheels
SITE=/tmp/csmlab-site
read -r -a PACKAGES <<< "${PACKAGES:-warp-lang colour-science flip-evaluator}"

pack() {
  local versions=() p v
  for p in "${PACKAGES[@]}"; do
    v=$("$PYTHON" -c "import importlib.metadata as m, sys; print(m.version(sys.argv[1]))" "$p") || return 1
    versions+=("$p==$v")
  done
  rm -rf .whl && mkdir -p .whl/download .whl/site || return 1
  "$PYTHON" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
    --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64 \
    --platform manylinux2014_x86_64 --platform manylinux1_x86_64 -d .whl/download "${versions[@]}" || return 1
  for w in .whl/download/*.whl; do "$PYTHON" -m zipfile -e "$w" .whl/site || return 1; done
  tar -C .whl/site -cf - . | xz -9 -T0 > .whl/site.tar.xz || return 1
  split -b "$PART_SIZE" -d -a 1 .whl/site.tar.xz .whl/part- || return 1
  local count sum k
  count=$(ls .whl/part-* | wc -l)
  sum=$(sha256sum .whl/site.tar.xz | cut -d' ' -f1)
  for k in $(seq 0 $((count - 1))); do
    mkdir -p ".whl/p$k" && mv ".whl/part-$k" ".whl/p$k/" && echo "$count $sum ${versions[*]}" > ".whl/p$k/manifest"
  done
  rm -rf .whl/download .whl/site .whl/site.tar.xz
  du -sh .whl/p*
  echo "carry .whl/p0 … .whl/p$((count - 1)) in as many device calls, back to back (see this script's header)"
}

# Keep the carried parts in $STORE; 0 once every part is there and unpacked into $SITE (or warp imports).
gather() {
  if "$PYTHON" -c "import warp, colour, flip_evaluator" 2>/dev/null; then
    return 0
  fi
  mkdir -p "$STORE"
  local d
  for d in .whl/p*; do
    [ -f "$d/manifest" ] && cp "$d"/part-* "$d/manifest" "$STORE/"
  done
  if [ ! -f "$STORE/manifest" ]; then
    echo "gpu_check: no wheels here and warp is not installed: run 'bash benchmarks/gpu_check.sh pack' where pip" \
         "works, then carry .whl/p0 …" >&2
    return 2
  fi
  local count sum have
  read -r count sum _ < "$STORE/manifest"
  have=$(ls "$STORE"/part-* | wc -l)
  if [ "$have" -lt "$count" ]; then
    echo "gpu_check: $have of $count wheel parts here ($(cd "$STORE" && ls part-* | tr '\n' ' '));" \
         "call again at once carrying the next .whl/pK"
    return 3
  fi
  if [ "$(cat "$STORE"/part-* | sha256sum | cut -d' ' -f1)" != "$sum" ]; then
    echo "gpu_check: the wheel parts do not match their manifest (parts of two packs?): pack again" >&2
    return 2
  fi
  rm -rf "$SITE" && mkdir -p "$SITE"
  cat "$STORE"/part-* | "$PYTHON" -c "import sys, tarfile; tarfile.open(fileobj=sys.stdin.buffer, mode='r|xz').extractall(sys.argv[1], filter='data')" "$SITE"
}

# Run one step under a time limit, its output to the terminal and to $OUT/$1.txt; remember the first failure.
STATUS=0
step() {
  local name=$1 limit=$2
  shift 2
  echo "=== $name (at most ${limit} s): $*"
  local start=$SECONDS
  timeout "$limit" "$@" 2>&1 | tee "$OUT/$name.txt"
  local rc=${PIPESTATUS[0]}
  echo "=== $name: exit $rc after $((SECONDS - start)) s" | tee -a "$OUT/$name.txt"
  [ "$STATUS" -ne 0 ] || STATUS=$rc
}

cuda_test_modules() {
  "$PYTHON" - <<'EOF'
import ast, pathlib
for path in sorted(pathlib.Path("tests").rglob("test_*.py")):
    tree = ast.parse(path.read_text(encoding="utf-8"))
    if any(isinstance(n, ast.FunctionDef) and n.name.startswith("test_") and any(a.arg == "device" for a in n.args.args)
           for n in ast.walk(tree)):
        print(path)
EOF
}

check() {
  mkdir -p "$OUT"
  export PYTHONPATH="$SITE:$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
  { nvidia-smi -L; git log -1 --format='commit %H %s' 2>/dev/null; "$PYTHON" --version
    "$PYTHON" -c "import warp as wp; wp.init(); print('warp', wp.__version__, 'cuda devices', wp.get_cuda_device_count())"
  } 2>&1 | tee "$OUT/machine.txt"
  if ! "$PYTHON" -c "import warp as wp; wp.init(); raise SystemExit(wp.get_cuda_device_count() == 0)" 2>/dev/null; then
    echo "gpu_check: Warp finds no CUDA device here (machine.txt): nothing to check" >&2
    return 2
  fi
  local parallel=()
  "$PYTHON" -c "import xdist" 2>/dev/null && parallel=(-n 8)
  # shellcheck disable=SC2046
  step tests_cuda 230 "$PYTHON" -m pytest $(cuda_test_modules) -k cuda -q -p no:cacheprovider -o addopts=-ra \
    "${parallel[@]}"
  step bench_frame_cuda_tiled 75 "$PYTHON" benchmarks/bench_frame.py --device cuda --raster tiled --repeats 5
  step bench_frame_cuda_walk 75 "$PYTHON" benchmarks/bench_frame.py --device cuda --raster walk --repeats 5
  step default_run_cuda 100 "$PYTHON" -m csmlab.cli run \
    --device cuda --jobs 8 --out /tmp/csmlab-default-cuda
  cp /tmp/csmlab-default-cuda/metrics.csv "$OUT/default_metrics.csv" 2>/dev/null
  cp /tmp/csmlab-default-cuda/timings.csv "$OUT/default_timings.csv" 2>/dev/null
  return "$STATUS"
}

engines() {
  mkdir -p "$OUT"
  export PYTHONPATH="$SITE:$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
  step engines_cuda 560 "$PYTHON" -m csmlab.cli run \
    experiments/engines.toml --frames 12 --device cuda --jobs 8 --out /tmp/csmlab-engines-cuda
  cp /tmp/csmlab-engines-cuda/metrics.csv "$OUT/engines_metrics.csv" 2>/dev/null
  return "$STATUS"
}

case "${1:-check}" in
  pack) pack ;;
  check) gather && check ;;
  engines) gather && engines ;;
  *) echo "usage: bash benchmarks/gpu_check.sh [pack|check|engines]" >&2; exit 2 ;;
esac
