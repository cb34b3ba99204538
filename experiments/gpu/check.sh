#!/usr/bin/env bash
# One-shot GPU check (experiments/gpu/README.md): install -> pytest -m gpu -> renderer parity vs gsplat's CUDA
# kernels -> env agent-frames/s on CUDA -> a short main job with device=cuda -> one summary table.
#
#   bash experiments/gpu/check.sh [OUT_DIR]          # on a CUDA machine, from the repository root (~8 min)
#   bash experiments/gpu/check.sh --dry [OUT_DIR]    # the same steps on CPU at toy sizes (checks this script)
#
# Every step has its own time limit (they add up to 7.5 min) and writes OUT_DIR/<step>.json; a failed or
# timed-out step is marked in the table and the next step runs. Exit status 1 when any step failed.
set -u -o pipefail
cd "$(dirname "$0")/../.."

DRY=0
if [ "${1:-}" = "--dry" ]; then DRY=1; shift; fi
OUT="${1:-outputs/gpu_check}"
mkdir -p "$OUT"
rm -f "$OUT"/*.json
PY="${PYTHON:-python}"
T0=$SECONDS

record() {  # step status seconds note  (for the shell steps)
  "$PY" - "$OUT" "$1" "$2" "$3" "$4" <<'EOF'
import json, sys
out, step, status, seconds, note = sys.argv[1:]
rec = {"step": step, "status": status, "seconds": float(seconds), "figures": {}, "note": note}
open(f"{out}/{step}.json", "w").write(json.dumps(rec))
print(json.dumps(rec))
EOF
}

status_of() { case $1 in 0) echo ok ;; 124|137) echo TIMEOUT ;; *) echo FAIL ;; esac; }

if [ "$DRY" = 1 ]; then
  DEVICE=cpu; BATCH="2 4"; RES="32"; STEPS=1
  record install skipped 0 "dry run: nothing installed"
else
  DEVICE=cuda; BATCH="64 256 1024"; RES="32 64 128"; STEPS=3
  # --- 1. install (90 s, plus up to 300 s for gsplat's first CUDA build): the package's dependencies and
  # gsplat. With a wheel folder (WHEELS, default .whl: experiments/gpu/wheels.sh) it installs from there with no
  # index and no resolution, and the package runs from this checkout (PYTHONPATH): an offline machine keeps its
  # own torch. Else pip installs ".[dev,gsplat]" from the index.
  t=$SECONDS
  WHEELS="${WHEELS:-.whl}"
  if compgen -G "$WHEELS/*.whl" > /dev/null; then
    timeout 90 "$PY" -m pip install -q --no-index --no-deps --no-compile "$WHEELS"/*.whl > "$OUT/install.log" 2>&1
    rc=$?; how="wheels from $WHEELS (no index)"
    export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}"
  else
    timeout 90 "$PY" -m pip install -q -e ".[dev,gsplat]" > "$OUT/install.log" 2>&1
    rc=$?; how='pip install -e ".[dev,gsplat]"'
  fi
  # what the later steps import; gsplat compiles its CUDA kernels on first use (minutes), here, once
  timeout 60 "$PY" -c "import torchrl, hydra, trimesh, wanderland_nav.train" >> "$OUT/install.log" 2>&1 || rc=1
  FAST_COMPILE=1 timeout 300 "$PY" -c "from gsplat.cuda._backend import _C; assert _C is not None" \
    >> "$OUT/install.log" 2>&1 || how="$how; gsplat's CUDA kernels not built"
  record install "$(status_of $rc)" $((SECONDS - t)) "$how; log: $OUT/install.log"
  "$PY" -c "import torch; assert torch.cuda.is_available(), 'torch sees no CUDA device'" || {
    record pytest_gpu FAIL 0 "torch sees no CUDA device"; "$PY" -m experiments.gpu.check summary --out "$OUT"; exit 1; }
fi

# --- 2. pytest -m gpu (90 s), on the test files that hold gpu tests (others may import packages this machine lacks)
t=$SECONDS
GPU_TESTS=$(grep -rlE "mark\.gpu|pytestmark.*gpu" tests | sort)
if [ "$DRY" = 1 ]; then
  # shellcheck disable=SC2086
  timeout 90 "$PY" -m pytest -m gpu --collect-only -q -p no:cacheprovider $GPU_TESTS > "$OUT/pytest_gpu.log" 2>&1
  rc=$?; note="dry: collected only ($(grep -c '::' "$OUT/pytest_gpu.log") gpu tests)"
else
  # shellcheck disable=SC2086
  timeout 90 "$PY" -m pytest -m gpu -q -p no:cacheprovider $GPU_TESTS > "$OUT/pytest_gpu.log" 2>&1
  rc=$?; note="$(tail -n 1 "$OUT/pytest_gpu.log")"
fi
record pytest_gpu "$(status_of $rc)" $((SECONDS - t)) "$note"

# --- 3. renderer parity vs gsplat (60 s) and 4. env agent-frames/s (150 s). The env camera's default backend,
# env.camera.render_backend=fused, is a CPU kernel with no CUDA form: on CUDA the camera renders with the torch path
# (env_fps records the backend each row ran on); the dry run renders with the fused kernel on CPU.
echo "note: the fused camera (env.camera.render_backend=fused) is CPU-only; on $DEVICE the camera renders with $( [ "$DEVICE" = cpu ] && echo fused || echo 'the torch path' )"
timeout 60 "$PY" -m experiments.gpu.check parity --out "$OUT" --device "$DEVICE" --res 64 \
  || { rc=$?; [ -f "$OUT/parity.json" ] || record parity "$(status_of $rc)" 60 "no record written"; }
# shellcheck disable=SC2086
timeout 150 "$PY" -m experiments.gpu.check env_fps --out "$OUT" --device "$DEVICE" --batch $BATCH --res $RES \
  --steps $STEPS || { rc=$?; [ -f "$OUT/env_fps.json" ] || record env_fps "$(status_of $rc)" 150 "no record written"; }

# --- 5. a short main job on the device (120 s): BC + a few PPO iterations + the evaluations at small sizes
t=$SECONDS
RUN="$OUT/main_job_run"
rm -rf "$RUN"
if [ "$DRY" = 1 ]; then SIZE=(debug=smoke); else
  SIZE=(algo.bc.rounds=2 algo.bc.updates_per_round=100 algo.ppo.total_frames=4000 algo.ppo.frames_per_batch=800
        algo.ppo.critic_warmup_iters=1 eval.episodes=50 eval.batch_size=50); fi
timeout 120 "$PY" -m wanderland_nav.train +exp=citywalker_rl device="$DEVICE" progress=false run_dir="$RUN" \
  "${SIZE[@]}" > "$OUT/main_job.log" 2>&1
rc=$?
quote='import json, sys
r = json.load(open(sys.argv[1]))
sr = {k: v["summary"]["overall"]["SR"] for k, v in r.items()}
print("%d test episodes: " % r["BC"]["summary"]["overall"]["episodes"] + ", ".join("%s SR %.3f" % kv for kv in sr.items()))'
record main_job "$(status_of $rc)" $((SECONDS - t)) \
  "$("$PY" -c "$quote" "$RUN/results.json" 2>/dev/null || echo "no results.json"); log: $OUT/main_job.log"

echo "total $((SECONDS - T0)) s"
"$PY" -m experiments.gpu.check summary --out "$OUT"
