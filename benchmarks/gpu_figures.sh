#!/usr/bin/env bash
# The camera and engine figures of docs/performance.md on a machine with a GPU (NVIDIA EGL), in
# one short run (about 4 minutes): which renderer skeye finds, the webcam frame's stages, the
# real-time streams (1 and 4 clients, ideal and webcam), the lockstep camera figure (1 and 10
# vehicles) and the engine against raw mj_step. Output goes to stdout and, when $OUT is set, to
# $OUT/gpu_figures.txt.
#
# Usage: benchmarks/gpu_figures.sh [PYTHON]    (default: .venv/bin/python, else python3)
set -u
cd "$(dirname "$0")/.."
PY=${1:-$( [ -x .venv/bin/python ] && echo .venv/bin/python || echo python3 )}
export MUJOCO_GL=egl PYTHONPATH=${PYTHONPATH:-$PWD}
LOG=${OUT:+$OUT/gpu_figures.txt}
LOG=${LOG:-/dev/null}
run() {
  echo "\$ $*" | tee -a "$LOG"
  timeout 150 "$@" 2>&1 | tee -a "$LOG"
}
{ date -u; uname -srm; nproc; uptime; nvidia-smi -L 2>&1 || true; } | tee -a "$LOG"
run "$PY" -c "from skeye import native; print(native.status().describe())"
run "$PY" benchmarks/bench_camera.py --stages --stage-repeats 5
run "$PY" benchmarks/bench_camera.py --seconds 5 --clients 1 4 --formats jpeg --profiles ideal webcam
run "$PY" benchmarks/bench_camera.py --only-lockstep --lockstep 1 10 --seconds 5
run "$PY" benchmarks/bench_limit.py --vehicles 1 10 --sim-seconds 3 --repeats 3
