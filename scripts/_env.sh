# Sourced by scripts/demo and scripts/test: create the project's own virtual
# environment (once) and install trackingbox with everything it needs.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${TRACKINGBOX_VENV:-$ROOT/.venv}"
PY="${PYTHON:-python3}"
if [ ! -x "$VENV/bin/python" ]; then
  echo "creating virtual environment $VENV" >&2
  "$PY" -m venv "$VENV"
fi
stamp="$VENV/.trackingbox-installed"
if [ ! -f "$stamp" ] || [ "$ROOT/pyproject.toml" -nt "$stamp" ]; then
  echo "installing trackingbox and its dependencies into $VENV" >&2
  "$VENV/bin/python" -m pip install --quiet --upgrade pip >&2
  "$VENV/bin/python" -m pip install --quiet -e "$ROOT[test]" >&2
  touch "$stamp"
fi
if ! command -v "${CC:-gcc}" >/dev/null 2>&1; then
  echo "error: no C compiler (${CC:-gcc}) on PATH: the embedded compile path needs one (apt-get install gcc)" >&2
  exit 2
fi
