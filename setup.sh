#!/usr/bin/env bash
# One entry point for a fresh Linux machine: checks the system libraries bpy needs,
# creates .venv with the pinned packages, then runs what you asked for:
#   bash setup.sh demo     track the bundled sample scene and print its error
#   bash setup.sh test     run the test suite
#   bash setup.sh build    build the installable extension zip into dist/
#   bash setup.sh env      only set up the environment
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
cd "$here"

# --- system libraries bpy loads at import time (Debian/Ubuntu package names) ---
missing=()
# Read the linker cache once: `ldconfig -p | grep -q` under pipefail fails at random (SIGPIPE).
known_libs="$(ldconfig -p 2>/dev/null || true)"
for pair in libX11.so.6:libx11-6 libXrender.so.1:libxrender1 libXfixes.so.3:libxfixes3 \
            libXi.so.6:libxi6 libxkbcommon.so.0:libxkbcommon0 libSM.so.6:libsm6 \
            libICE.so.6:libice6 libXext.so.6:libxext6 libGL.so.1:libgl1 libEGL.so.1:libegl1; do
  lib="${pair%%:*}"; pkg="${pair##*:}"
  case "$known_libs" in *"$lib"*) ;; *) missing+=("$pkg") ;; esac
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup.sh: bpy needs system libraries that are missing: ${missing[*]}" >&2
  echo "  install them with:  sudo apt-get install -y ${missing[*]}" >&2
  exit 3
fi

# --- Python 3.11 (bpy 5.0.1 is built for CPython 3.11 only) ---
py="${PYTHON:-}"
if [ -z "$py" ]; then
  for cand in python3.11 python3; do
    if command -v "$cand" >/dev/null && "$cand" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
      py="$cand"; break
    fi
  done
fi
if [ -z "$py" ]; then
  echo "setup.sh: Python 3.11 is required (bpy 5.0.1 supports only 3.11)." >&2
  echo "  install it (e.g. 'sudo apt-get install python3.11 python3.11-venv' or pyenv) or set PYTHON=/path/to/python3.11" >&2
  exit 3
fi

venv="$here/.venv"
stamp="$venv/.requirements.sha"
want="$(sha256sum requirements.txt | cut -d' ' -f1)"
if [ ! -x "$venv/bin/python" ] || [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  echo "setup.sh: creating $venv with the pinned packages (about 1.3 GB, once)" >&2
  "$py" -m venv "$venv"
  "$venv/bin/python" -m pip install -q --disable-pip-version-check -r requirements.txt
  echo "$want" > "$stamp"
fi
# `python -m markerless_mocap` must work whatever this folder is called: expose the
# repository root under the extension's id inside the venv.
site="$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
ln -sfn "$here" "$site/markerless_mocap"

cmd="${1:-env}"; shift || true
case "$cmd" in
  env)   echo "setup.sh: environment ready: $venv/bin/python -m markerless_mocap --help" ;;
  demo)  exec "$venv/bin/python" -m markerless_mocap demo "$@" ;;
  test)  exec "$venv/bin/python" -m pytest -q "$here/tests" "$@" ;;
  build) exec "$venv/bin/python" -m markerless_mocap build "$@" ;;
  *)     exec "$venv/bin/python" -m markerless_mocap "$cmd" "$@" ;;
esac
