#!/bin/bash
# usage: trial5.sh NAME SEED [overrides...] -> main-job PPO (citywalker_rl, 28,800 frames) from that seed's cached BC, val
name=$1; seed=$2; shift 2
cd /work/wt/learning && source /work/venv/bin/activate
PYTHONPATH=$PWD OMP_NUM_THREADS=1 exec python -m wanderland_nav.train +exp=citywalker_rl seed=$seed threads=1 progress=false \
  init_checkpoint=/tmp/learning/bc/seed$seed.pt eval.split=val run_dir=/tmp/learning/runs5/${name}_s$seed "$@" \
  > /tmp/learning/logs5/${name}_s$seed.log 2>&1
