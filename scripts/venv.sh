# Sourced by the README's commands: create or reuse .venv in the repository root and make sure
# the package and everything it needs are installed in it (re-installs when setup.py changes).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
if [ ! -x "$VENV/bin/python" ]; then
    echo "[ecahd] creating virtual environment at $VENV"
    python3 -m venv "$VENV"
fi
STAMP="$VENV/.ecahd-installed"
WANT="$(cat "$ROOT/setup.py" "$ROOT/setup.cfg" "$ROOT"/interfaces/*/package.xml "$ROOT"/interfaces/*/CMakeLists.txt \
    "$ROOT"/interfaces/*/msg/* "$ROOT"/interfaces/*/action/* "$ROOT/scripts/build_interfaces.sh" | sha256sum | cut -d' ' -f1)"
if [ ! -f "$STAMP" ] || [ "$(cat "$STAMP")" != "$WANT" ]; then
    echo "[ecahd] installing ecahd_ros and its dependencies into $VENV"
    "$VENV/bin/python" -m pip install --quiet --upgrade pip
    "$VENV/bin/python" -m pip install --quiet -e "$ROOT[test,interfaces]"
    mkdir -p "$VENV/.interfaces"
    bash "$ROOT/scripts/build_interfaces.sh" "$VENV"
    echo "$WANT" > "$STAMP"
fi
export PATH="$VENV/bin:$PATH"
export MPLBACKEND=Agg
