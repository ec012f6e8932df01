#!/usr/bin/env bash
# The real-Blender stage: Debian 13's Blender 4.3.2 (Python 3.13) in a debootstrap chroot.
#   1. provision the chroot once (cached under $MOCAP_STAGE_CACHE, default /var/cache/markerless_mocap)
#   2. enable the add-on from this checkout, run `blender -b SUBJECT --command markerless_mocap track`
#      on a sample scene (few frames, small budget) and check every result file
#   3. start the UI under Xvfb and drive Import, Check, Track (modal), Esc and Export; screenshots
# Exit 0 = passed, 77 = skipped (cannot provision here; the reason is printed), anything else = failed.
#   bash tests/real_blender/stage.sh [--provision-only | --resave-subjects]
#   --resave-subjects: rebuild every sample_scenes/*/subject.blend from its subject_source.json.gz with
#   this Blender 4.3.2, the oldest real Blender at hand (files it saves open in 4.2-5.2).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
cache="${MOCAP_STAGE_CACHE:-/var/cache/markerless_mocap}"
root="$cache/trixie-blender"
out="${MOCAP_STAGE_OUT:-$repo/results/real_blender}"
mirror="${MOCAP_STAGE_MIRROR:-http://deb.debian.org/debian}"
t0=$(date +%s)
log() { echo "[stage $(( $(date +%s) - t0 ))s] $*"; }
skip() { echo "real-Blender stage SKIPPED: $*" >&2; exit 77; }

[ "$(uname -s)-$(uname -m)" = "Linux-x86_64" ] || skip "needs Linux x86-64 (Debian's Blender package)"
[ "$(id -u)" = 0 ] || skip "needs root for debootstrap/chroot (run as root, or provision $root as root once)"

mounted=()
cleanup() {
  local i
  for (( i=${#mounted[@]}-1; i>=0; i-- )); do umount -l "${mounted[$i]}" 2>/dev/null || true; done
}
trap cleanup EXIT
mnt() {  # mnt SRC DST [opts...]: bind-mount and remember
  local src="$1" dst="$2"; shift 2
  mkdir -p "$dst"
  mount "$@" "$src" "$dst"
  mounted+=("$dst")
}

provision() {
  local tmp="$root.partial"
  rm -rf "$tmp"
  mkdir -p "$cache"
  if ! command -v debootstrap >/dev/null; then
    log "installing debootstrap"
    { apt-get install -y -q debootstrap >/dev/null 2>&1 || { apt-get update -q >/dev/null 2>&1 && apt-get install -y -q debootstrap >/dev/null 2>&1; }; } \
      || skip "debootstrap is not installed and apt-get cannot install it"
  fi
  log "debootstrap trixie into $tmp (about 2 min, once)"
  debootstrap --variant=minbase trixie "$tmp" "$mirror" > "$cache/debootstrap.log" 2>&1 \
    || skip "debootstrap of Debian 13 failed (no access to $mirror?); see $cache/debootstrap.log"
  mnt proc "$tmp/proc" -t proc
  mnt /dev "$tmp/dev" --bind
  mnt /sys "$tmp/sys" --bind
  cp /etc/resolv.conf "$tmp/etc/resolv.conf" 2>/dev/null || true
  log "apt-get install blender and the UI tools in the chroot (about 3 min, once)"
  chroot "$tmp" /usr/bin/env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends \
      blender xvfb xauth imagemagick xdotool python3-scipy python3-opencv python3-numba \
      libgl1-mesa-dri > "$cache/apt.log" 2>&1 \
    || skip "apt-get install blender in the Debian 13 chroot failed; see $cache/apt.log"
  chroot "$tmp" apt-get clean >/dev/null 2>&1 || true
  cleanup; mounted=()
  mv "$tmp" "$root"
  touch "$root/.ready"
}

if [ ! -e "$root/.ready" ]; then
  provision
else
  log "using the cached chroot $root"
fi
chroot "$root" blender --version 2>/dev/null | head -1 | sed 's/^/[stage] /'
[ "${1:-}" = "--provision-only" ] && exit 0

# --- the checkout inside the chroot: /mnt/mocap/markerless_mocap (the extension id as folder name)
src=/mnt/mocap/markerless_mocap
mnt proc "$root/proc" -t proc
mnt /dev "$root/dev" --bind
mnt /sys "$root/sys" --bind
mnt "$repo" "$root$src" --bind
export PYTHONDONTWRITEBYTECODE=1  # no Python 3.13 caches in the checkout

if [ "${1:-}" = "--resave-subjects" ]; then
  for scene in "$repo"/sample_scenes/*/; do
    name="$(basename "$scene")"
    [ -f "$scene/subject_source.json.gz" ] || continue
    chroot "$root" blender -b --factory-startup --python-exit-code 1 --python "$src/tools/portable_subject.py" -- \
      build "$src/sample_scenes/$name/subject_source.json.gz" "$src/sample_scenes/$name/subject.blend" 2>&1 \
      | grep -E "portable_subject|Error" || { echo "resave of $name failed" >&2; exit 1; }
  done
  exit 0
fi
