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
  # --- 1. install (90 s): the package with its test extras and gsplat's CUDA kernels
  t=$SECONDS
  timeout 90 "$PY" -m pip install -q -e ".[dev,gsplat]" > "$OUT/install.log" 2>&1
  rc=$?
  record install "$(status_of $rc)" $((SECONDS - t)) "pip install -e .[dev,gsplat]; log: $OUT/install.log"
  "$PY" -c "import torch; assert torch.cuda.is_available(), 'torch sees no CUDA device'" || {
    record pytest_gpu FAIL 0 "torch sees no CUDA device"; "$PY" -m experiments.gpu.check summary --out "$OUT"; exit 1; }
fi

# --- 2. pytest -m gpu (90 s)
t=$SECONDS
if [ "$DRY" = 1 ]; then
  timeout 90 "$PY" -m pytest -m gpu --collect-only -q -p no:cacheprovider > "$OUT/pytest_gpu.log" 2>&1
  rc=$?; note="dry: collected only ($(grep -c '::' "$OUT/pytest_gpu.log") gpu tests)"
else
  timeout 90 "$PY" -m pytest -m gpu -q -p no:cacheprovider > "$OUT/pytest_gpu.log" 2>&1
  rc=$?; note="$(tail -n 1 "$OUT/pytest_gpu.log")"
fi
record pytest_gpu "$(status_of $rc)" $((SECONDS - t)) "$note"

# --- 3. renderer parity vs gsplat (60 s) and 4. env agent-frames/s (150 s)
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
record main_job "$(status_of $rc)" $((SECONDS - t)) \
  "$(grep -E '^(BC\+RL|BC) ' "$OUT/main_job.log" | head -n 2 | tr -s ' ' | cut -c1-60 | paste -sd ';' -); log: $OUT/main_job.log"

echo "total $((SECONDS - T0)) s"
"$PY" -m experiments.gpu.check summary --out "$OUT"
