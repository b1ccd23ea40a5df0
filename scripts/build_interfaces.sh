#!/usr/bin/env bash
# Build the interface packages ROS 2 Jazzy has but PyPI does not (interfaces/: tf2_msgs, nav2_msgs' NavigateToPose and ComputePathToPose) into a
# virtual environment, so rclpy can use them: `bash scripts/build_interfaces.sh [VENV]` (default:
# the repository's .venv; scripts/venv.sh calls it). Needs the `interfaces` extra installed
# (the rosidl generators, ament_cmake, colcon), cmake and a C/C++ compiler. Takes ~30 s.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${1:-$ROOT/.venv}"
PY="$VENV/bin/python"
SITE="$("$PY" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
# The PyPI wheels' CMake files name the include folders of the container they were built in;
# point them at this interpreter's and numpy's (idempotent).
PYINC="$("$PY" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')"
NPINC="$("$PY" -c 'import numpy; print(numpy.get_include())')"
{ grep -rlE '/opt/python/cp[0-9]+-cp[0-9]+/' --include='*.cmake' "$VENV/share" 2>/dev/null || true; } \
    | while read -r f; do
        sed -i -E "s#/opt/python/cp[0-9]+-cp[0-9]+/lib/python[0-9.]+/site-packages/numpy/(_core|core)/include#$NPINC#g; s#/opt/python/cp[0-9]+-cp[0-9]+/include/python[0-9.]+#$PYINC#g" "$f"
    done
export AMENT_PREFIX_PATH="$VENV" CMAKE_PREFIX_PATH="$VENV"
for pkg in "$ROOT"/interfaces/*/; do
    name="$(basename "$pkg")"
    echo "[ecahd] building $name into $VENV"
    "$VENV/bin/colcon" --log-base "$VENV/.interfaces/log" build --base-paths "$pkg" \
        --build-base "$VENV/.interfaces/build" --install-base "$VENV" --merge-install \
        --event-handlers console_direct- console_stderr- \
        --cmake-args -DPython3_EXECUTABLE="$PY" -DBUILD_TESTING=OFF > "$VENV/.interfaces/$name.log" 2>&1 \
        || { echo "[ecahd] building $name failed; its log: $VENV/.interfaces/$name.log" >&2
             tail -20 "$VENV/.interfaces/$name.log" >&2; exit 1; }
done
# the built Python packages land in the venv's site-packages, their libraries in its lib/
# (the ROS wheels' bootstrapper puts that on the loader path)
"$PY" -c 'import tf2_msgs.msg, nav2_msgs.action' \
    || { echo "[ecahd] the interfaces built but do not import" >&2; exit 1; }
echo "[ecahd] interfaces ready in $SITE"
