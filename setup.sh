#!/usr/bin/env bash
# One entry point for a fresh Linux machine: checks the system libraries bpy needs,
# creates .venv with the pinned packages, then runs what you asked for:
#   bash setup.sh demo     track the bundled sample scene and print its error
#   bash setup.sh test     lint (ruff, settings in pyproject.toml), run the test suite (bpy 5.0.1, Python 3.11),
#                          then a subset on bpy 5.2.3 (Python 3.13, .venv313) when a Python 3.13 is found, or
#                          say that it is skipped
#   bash setup.sh build    build the installable extension zips into dist/, one per platform (linux-x64,
#                          windows-x64, macos-arm64); --all-platforms makes one zip for all three
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
  echo "setup.sh: installing the pinned packages of requirements.txt into $venv (about 1.3 GB the first time)" >&2
  "$py" -m venv "$venv"
  "$venv/bin/python" -m pip install -q --disable-pip-version-check -r requirements.txt
  echo "$want" > "$stamp"
fi
# `python -m markerless_mocap` must work whatever this folder is called: expose the
# repository root under the extension's id inside the venv.
site="$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
ln -sfn "$here" "$site/markerless_mocap"

# --- Python 3.13 (Blender 5.1 / 5.2 LTS, bpy 5.2.3): found on PATH, in $PYTHON313, or in pyenv ---
find_python313() {
  local cand root
  for cand in "${PYTHON313:-}" python3.13; do
    if [ -n "$cand" ] && command -v "$cand" >/dev/null && \
       "$cand" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 13))' 2>/dev/null; then
      command -v "$cand"; return 0
    fi
  done
  root="$(pyenv root 2>/dev/null || echo "${PYENV_ROOT:-$HOME/.pyenv}")"
  for cand in "$root"/versions/3.13*/bin/python3.13; do
    if [ -x "$cand" ] && "$cand" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 13))' 2>/dev/null; then
      echo "$cand"; return 0
    fi
  done
  return 1
}

venv313="$here/.venv313"
setup_venv313() {  # prints nothing and returns 1 when there is no Python 3.13
  local py313 want313
  py313="$(find_python313)" || return 1
  want313="$(sha256sum requirements-py313.txt | cut -d' ' -f1)"
  if [ ! -x "$venv313/bin/python" ] || [ "$(cat "$venv313/.requirements.sha" 2>/dev/null)" != "$want313" ]; then
    echo "setup.sh: creating $venv313 with $py313 and requirements-py313.txt (bpy 5.2.3, about 1.4 GB, once)" >&2
    rm -rf "$venv313"
    "$py313" -m venv "$venv313"
    "$venv313/bin/python" -m pip install -q --disable-pip-version-check -r requirements-py313.txt
    echo "$want313" > "$venv313/.requirements.sha"
  fi
  ln -sfn "$here" "$("$venv313/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')/markerless_mocap"
}

# The Blender 5.1/5.2 subset: every test file that checks the Blender/Python/numpy boundary, plus one
# short tracking run on numpy 2 (about 3 min on the 2-core machines).
PY313_TESTS=(tests/test_build_install.py tests/test_addon_ui.py tests/test_export.py
             "tests/test_tracking.py::test_a_few_tracked_frames_stay_near_the_truth"
             "tests/test_sample_scenes.py::test_subject_opens_and_is_version_neutral")

cmd="${1:-env}"; shift || true
case "$cmd" in
  env)   echo "setup.sh: environment ready: $venv/bin/python -m markerless_mocap --help" ;;
  demo)  exec "$venv/bin/python" -m markerless_mocap demo "$@" ;;
  test)
    rc=0
    echo "setup.sh: lint: ruff check (rules in pyproject.toml)" >&2
    if ! "$venv/bin/ruff" check "$here"; then
      echo "setup.sh: ruff found the problems listed above; fix them (the tests do not run until the lint is clean)" >&2
      exit 1
    fi
    echo "setup.sh: test suite on bpy 5.0.1 (Python 3.11, $venv)" >&2
    "$venv/bin/python" -m pytest -q "$here/tests" "$@" || rc=$?
    if setup_venv313; then
      echo "setup.sh: Blender 5.1/5.2 subset on bpy 5.2.3 (Python 3.13, $venv313): ${PY313_TESTS[*]}" >&2
      "$venv313/bin/python" -m pytest -q -p no:cacheprovider "${PY313_TESTS[@]}" "$@" || rc=$?
    else
      echo "setup.sh: SKIPPED the Blender 5.1/5.2 subset (bpy 5.2.3): no Python 3.13 found on PATH, in" \
           "\$PYTHON313 or in pyenv; install one (e.g. pyenv install 3.13) to run it" >&2
    fi
    exit "$rc" ;;
  env313) setup_venv313 || { echo "setup.sh: no Python 3.13 found (PATH, \$PYTHON313, pyenv)" >&2; exit 3; }
          echo "setup.sh: environment ready: $venv313/bin/python" ;;
  build) exec "$venv/bin/python" -m markerless_mocap build "$@" ;;
  *)     exec "$venv/bin/python" -m markerless_mocap "$cmd" "$@" ;;
esac
