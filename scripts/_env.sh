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
# The stamp names the checkout installed (editable) into the environment. An environment
# shared through TRACKINGBOX_VENV with another checkout is refused, not silently re-pointed.
if [ -s "$stamp" ] && [ "$(cat "$stamp")" != "$ROOT" ]; then
  echo "error: $VENV has trackingbox installed from $(cat "$stamp"), not from $ROOT;" \
       "installing here would re-point it: set TRACKINGBOX_VENV to an environment of this checkout" >&2
  exit 2
fi
if [ ! -f "$stamp" ] || [ "$ROOT/pyproject.toml" -nt "$stamp" ]; then
  echo "installing trackingbox and its dependencies into $VENV" >&2
  "$VENV/bin/python" -m pip install --quiet --upgrade pip >&2
  "$VENV/bin/python" -m pip install --quiet -e "$ROOT[test]" >&2
  printf '%s' "$ROOT" > "$stamp"
fi
if ! command -v "${CC:-gcc}" >/dev/null 2>&1; then
  echo "error: no C compiler (${CC:-gcc}) on PATH: the embedded compile path needs one (apt-get install gcc)" >&2
  exit 2
fi
