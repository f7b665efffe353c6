#!/usr/bin/env bash
# The camera and engine figures of docs/performance.md on a machine with a GPU (NVIDIA EGL), in
# one short run (about 4 minutes): which renderer skeye finds, the webcam frame's stages, the
# real-time streams (1 and 4 clients, ideal and webcam), the lockstep camera figure (1 and 10
# vehicles), examples/takeoff_land.py in lockstep with and without --image-port, and the engine
# against raw mj_step (meaningful only where the hot path is compiled: the first line says).
# Output goes to stdout and, when $OUT is set, to $OUT/gpu_figures.txt.
#
# Usage: benchmarks/gpu_figures.sh [PYTHON]    (default: .venv/bin/python, else python3)
set -u
cd "$(dirname "$0")/.."
PY=${1:-$( [ -x .venv/bin/python ] && echo .venv/bin/python || echo python3 )}
export MUJOCO_GL=egl PYTHONPATH=${PYTHONPATH:-$PWD}
LOG=${OUT:+$OUT/gpu_figures.txt}
LOG=${LOG:-/dev/null}
# Each command runs in the background of this script, and the script waits for it: a trap runs
# at once only then. `timeout` puts the command in a process group of its own, out of reach of a
# terminal's Ctrl-C, so the trap hands the signal on to that group (the benchmark and the
# simulators it started) and stops the script there.
child="" sim=""
exec {stderr}>&2  # the trap's own, whatever the interrupted command's output went to
stop() {
  trap - INT TERM
  [ -n "$child" ] && kill -INT -- "-$child" 2>/dev/null && wait "$child"
  [ -n "$sim" ] && kill "$sim" 2>/dev/null && wait "$sim"
  echo "gpu_figures.sh: interrupted" | tee -a "$LOG" >&"$stderr"
  exit 130
}
trap stop INT TERM
waited() {  # timeout 150 COMMAND... in the background, waited for; its status
  timeout 150 "$@" &
  child=$!
  wait "$child"
  local rc=$?
  child=""
  return $rc
}
run() {
  echo "\$ $*" | tee -a "$LOG"
  local out tee_pid
  exec {out}> >(tee -i -a "$LOG")  # -i: the benchmark's last lines after a Ctrl-C
  tee_pid=$!
  waited "$@" >&"$out" 2>&1
  exec {out}>&-
  wait "$tee_pid"  # its last lines before the next command's
}
{ date -u; uname -srm; nproc; uptime; nvidia-smi -L 2>&1 || true; } | tee -a "$LOG"
run "$PY" -c "from skeye import native; print(native.status().describe())"
run "$PY" benchmarks/bench_camera.py --stages --stage-repeats 5
run "$PY" benchmarks/bench_camera.py --seconds 5 --clients 1 4 --formats jpeg --profiles ideal webcam
run "$PY" benchmarks/bench_camera.py --only-lockstep --lockstep 1 10 --seconds 5
run "$PY" benchmarks/bench_limit.py --vehicles 1 10 --sim-seconds 3 --repeats 3

# examples/takeoff_land.py against a lockstep simulator, without and with an image server
for images in "" "--image-port 0"; do
  "$PY" -m skeye.cli sim --mode lockstep --port 0 $images > /tmp/skeye_gpu_sim.log 2>&1 &
  sim=$!
  for _ in $(seq 300); do grep -q "bound to" /tmp/skeye_gpu_sim.log && break; sleep 0.1; done
  port=$(sed -n 's/.*control protocol on [0-9.]*:\([0-9]*\).*/\1/p' /tmp/skeye_gpu_sim.log)
  start=$(date +%s%N)
  SKEYE_SIM=127.0.0.1:$port waited "$PY" examples/takeoff_land.py > /dev/null 2>&1
  rc=$?
  took_ms=$(( ($(date +%s%N) - start) / 1000000 ))
  echo "takeoff_land.py, lockstep ${images:-without images}: ${took_ms} ms (rc $rc)" | tee -a "$LOG"
  kill $sim; wait $sim 2>/dev/null
  sim=""
done
