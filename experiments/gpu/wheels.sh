#!/usr/bin/env bash
# The wheels `check.sh` installs on a CUDA machine that cannot reach a package index, fetched here (a machine
# with PyPI) into DIR for that machine's Python. Only what a CUDA PyTorch image usually lacks (~30 MB):
# torch is never fetched (the machine keeps its CUDA build), nor numpy, scipy, pytest and the like.
#
#   bash experiments/gpu/wheels.sh [DIR] [PYTHON_VERSION]     # default: .whl (git-ignored) and 3.12
#
# Then copy DIR to the repository root of the CUDA machine (or carry it) and run `bash experiments/gpu/check.sh`:
# it installs from DIR with no index and no dependency resolution, and says which import still fails.
set -euo pipefail
cd "$(dirname "$0")/../.."
DIR="${1:-.whl}"
PYV="${2:-3.12}"
PY="${PYTHON:-python}"
mkdir -p "$DIR"

# The project's own pins (pyproject.toml), plus the dependencies of those packages that such images lack.
BINARY=(
  "torchrl==0.14.1" "tensordict>=0.14,<0.15" hoptorch pyvers orjson importlib_metadata
  "hydra-core>=1.3,<1.4" "omegaconf>=2.2,<2.4" "trimesh>=4.4" "shapely>=2.1" "rtree>=1.2" "embreex>=4.3" "plyfile>=1.1,<2"
  "pytest-timeout>=2.3" "gsplat>=1.5,<2"
)
"$PY" -m pip download -q --no-deps --only-binary=:all: --python-version "$PYV" --implementation cp \
  --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_24_x86_64 \
  --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 -d "$DIR" "${BINARY[@]}"
# hydra-core's parser runtime is published as a source archive only: built here into a pure-Python wheel.
"$PY" -m pip wheel -q --no-deps -w "$DIR" "antlr4-python3-runtime==4.9.3"
ls -1 "$DIR"/*.whl
du -sh "$DIR"
