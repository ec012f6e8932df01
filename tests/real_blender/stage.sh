#!/usr/bin/env bash
# The real-Blender stage: Debian 13's Blender 4.3.2 (Python 3.13) in a debootstrap chroot.
#   1. provision the chroot once (cached under $MOCAP_STAGE_CACHE, default /var/cache/markerless_mocap)
#   2. enable the add-on from this checkout, run `blender -b SUBJECT --command markerless_mocap track`
#      on a sample scene (few frames, small budget) and check every result file
#   3. start the UI under Xvfb and drive Import, Check, Track (the actor's fit first, then tracking; both modal),
#      Esc and Export, with screenshots; then Track (modal) for the duet scene's two armatures, each actor's build
#      fitted first (modal, one after the other)
# Exit 0 = passed, 77 = skipped (cannot provision here; the reason is printed), anything else = failed.
#   bash tests/real_blender/stage.sh [--provision-only | --resave-subjects | --readme-screenshot]
#   --readme-screenshot: track the walk scene whole with the defaults in the UI and save the sidebar's picture
#   as docs/mocap_sidebar_finished.png (the README's).
#   --resave-subjects: rebuild every sample_scenes/*/subject.blend from its subject_source.json.gz, and
#   sample_scenes/characters/NAME.blend from NAME_source.json.gz, with this Blender 4.3.2, the oldest real
#   Blender at hand (files it saves open in 4.2-5.2).
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
  set +e
  local i
  for (( i=${#mounted[@]}-1; i>=0; i-- )); do umount -l "${mounted[$i]}" 2>/dev/null; done
  return 0
}
trap cleanup EXIT
unmount_under() {  # stale mounts of an interrupted run (never rm -rf through a bind mount of /dev)
  local m
  for m in $(awk -v d="$1/" 'index($2, d) == 1 {print $2}' /proc/mounts | sort -r); do umount -l "$m" || true; done
}
mnt() {  # mnt SRC DST [opts...]: bind-mount and remember
  local src="$1" dst="$2"; shift 2
  mkdir -p "$dst"
  mount "$@" "$src" "$dst"
  mounted+=("$dst")
}

provision() {
  local tmp="$root.partial"
  unmount_under "$tmp"
  rm -rf --one-file-system "$tmp"
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

unmount_under "$root"
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
  # the characters that receive the motion (sample_scenes/characters/NAME.blend from NAME_source.json.gz)
  for source in "$repo"/sample_scenes/characters/*_source.json.gz; do
    [ -f "$source" ] || continue
    name="$(basename "$source" _source.json.gz)"
    chroot "$root" blender -b --factory-startup --python-exit-code 1 --python "$src/tools/portable_subject.py" -- \
      build "$src/sample_scenes/characters/${name}_source.json.gz" "$src/sample_scenes/characters/$name.blend" 2>&1 \
      | grep -E "portable_subject|Error" || { echo "resave of character $name failed" >&2; exit 1; }
  done
  exit 0
fi

# --- what the stage needs from the checkout
venv_py="$repo/.venv/bin/python"
[ -x "$venv_py" ] || skip "no $repo/.venv (run 'bash setup.sh env' first: the stage bundles the add-on's wheels with it)"
rm -rf "$out"; mkdir -p "$out"
mnt "$out" "$root/mnt/out" --bind
fail() { echo "real-Blender stage FAILED: $*" >&2; exit 1; }
run_in() { chroot "$root" /usr/bin/env BLENDER_USER_RESOURCES=/mnt/out/blender_user PYTHONDONTWRITEBYTECODE=1 \
             NUMBA_CACHE_DIR=/var/cache/mocap-numba MOCAP_CACHE_DIR=/var/cache/mocap-motion "$@"; }

# 1. enable the add-on from the checkout, as a local extension repository; preferences saved
run_in blender -b --python-exit-code 1 --python "$src/tests/real_blender/enable_addon.py" -- /mnt/mocap \
  > "$out/enable.log" 2>&1 || fail "enabling the add-on failed; see $out/enable.log"
grep '^STAGE' "$out/enable.log" | sed 's/^STAGE/[stage]/'
# 2. the add-on's Python packages as a user's Blender gets them: the cp313 wheels the extension zip
#    bundles, unpacked where Blender unpacks an extension's wheels (Debian's own OpenCV 4.10 has no
#    TFLite importer, so the learned evidence needs the bundled one). After the first start: Blender's
#    extension start-up removes wheels that no installed extension lists from that folder
pyver="$(run_in blender -b --factory-startup --python-expr 'import sys; print("PYVER %d.%d" % sys.version_info[:2])' 2>/dev/null \
         | sed -n 's/^PYVER //p')"
[ -n "$pyver" ] || fail "Blender in the chroot does not start"
log "building the extension zip for linux-x64 (wheels from dist/wheels-cache, else PyPI)"
"$venv_py" -m markerless_mocap build --platforms linux-x64 --out "$out/zip" > "$out/build.log" 2>&1 \
  || fail "the extension build failed; see $out/build.log"
zip_path="$(ls "$out"/zip/*.zip)"
site="$out/blender_user/extensions/.local/lib/python$pyver/site-packages"
"$venv_py" - "$zip_path" "$site" "$pyver" <<'PY' || fail "could not unpack the bundled wheels"
import io, sys, zipfile
zip_path, site, pyver = sys.argv[1], sys.argv[2], tuple(int(x) for x in sys.argv[3].split("."))
from markerless_mocap.tools import wheels
with zipfile.ZipFile(zip_path) as zf:
    names = [n for n in zf.namelist() if n.startswith("wheels/") and n.endswith(".whl")]
    used = [n for n in names if wheels.wheel_fits(n.split("/")[-1], "linux-x64", pyver)]
    for n in used:
        zipfile.ZipFile(io.BytesIO(zf.read(n))).extractall(site)
print(f"[stage] unpacked {len(used)} of the zip's {len(names)} wheels for Python {sys.argv[3]}: "
      + ", ".join(n.split("/")[-1].split("-")[0] for n in used))
PY

packages="$(run_in blender -b --python-expr 'import cv2, scipy, numba, numpy; print("STAGE packages: numpy", numpy.__version__, "(Blender'"'"'s) cv2", cv2.__version__, "scipy", scipy.__version__, "numba", numba.__version__, "from", cv2.__file__)' \
  2>/dev/null | grep '^STAGE' | sed 's/^STAGE/[stage]/')"
echo "$packages"
case "$packages" in *"/extensions/.local/"*) ;; *) fail "Blender does not import the bundled wheels";; esac

start_xvfb() {  # a virtual screen for the UI runs; sets $display and $xvfb_pid
  rm -f "$out/xvfb.display"
  chroot "$root" Xvfb -displayfd 1 -screen 0 1600x1200x24 -nolisten tcp > "$out/xvfb.display" 2> "$out/xvfb.log" &
  xvfb_pid=$!
  trap 'kill "$xvfb_pid" 2>/dev/null || true; cleanup' EXIT
  for _ in $(seq 50); do [ -s "$out/xvfb.display" ] && break; sleep 0.2; done
  display="$(head -1 "$out/xvfb.display")"
  [ -n "$display" ] || fail "Xvfb did not start; see $out/xvfb.log"
}
drive_ui() {  # drive_ui SECONDS OUT_IN_CHROOT [--full-take]: Blender's UI on the walk scene, driven by drive_ui.py
  local seconds="$1"; shift
  timeout "$seconds" chroot "$root" /usr/bin/env DISPLAY=":$display" BLENDER_USER_RESOURCES=/mnt/out/blender_user \
    PYTHONDONTWRITEBYTECODE=1 NUMBA_CACHE_DIR=/var/cache/mocap-numba MOCAP_CACHE_DIR=/var/cache/mocap-motion \
    blender "$src/sample_scenes/walk/subject.blend" --window-geometry 0 0 1600 1200 --enable-event-simulate \
    --python "$src/tests/real_blender/drive_ui.py" -- "$src/sample_scenes/walk" "$@"
}

if [ "${1:-}" = "--readme-screenshot" ]; then
  # The README's picture of the panel: the walk scene tracked whole with the defaults in the real UI.
  start_xvfb
  log "UI on Xvfb :$display: the whole walk take with the default settings (a few minutes)"
  drive_ui 1200 /mnt/out/readme --full-take > "$out/readme.log" 2>&1 || fail "the full-take UI run failed; see $out/readme.log"
  grep '^STAGE-UI' "$out/readme.log" | sed 's/^STAGE-UI/[stage-ui]/'
  [ -s "$out/readme/finished_take.png" ] || fail "no screenshot of the finished take; see $out/readme.log"
  cp "$out/readme/finished_take.png" "$repo/docs/mocap_sidebar_finished.png"
  log "docs/mocap_sidebar_finished.png written"
  exit 0
fi

# 3. every sample scene's subject opens in this Blender
rc=0
run_in blender -b --python-exit-code 1 --python "$src/tests/real_blender/open_subjects.py" -- "$src/sample_scenes" \
  > "$out/subjects.log" 2>&1 || rc=$?
grep '^STAGE' "$out/subjects.log" | sed 's/^STAGE/[stage]/'
[ $rc = 0 ] || fail "a sample subject does not open in Blender 4.3.2; see $out/subjects.log"

# 4. the headless command, as a user runs it
log "blender -b walk/subject.blend --command markerless_mocap track (frames 0-2, 30 x 4)"
track_args=(track --capture "$src/sample_scenes/walk" --frames 0-2 --particles 30 --iterations 4)
t1=$(date +%s)
run_in blender -b "$src/sample_scenes/walk/subject.blend" --command markerless_mocap "${track_args[@]}" \
  --out /mnt/out/command_result > "$out/command.log" 2>&1 || fail "the --command run exited with $?; see $out/command.log"
log "--command run took $(( $(date +%s) - t1 )) s"
grep -q Traceback "$out/command.log" && fail "the --command run printed a traceback; see $out/command.log"
expected=(joints.npz poses.npz keypoints.npz report.json animation.bvh animation.fbx tracked.blend checkpoint.npz
          overlay/cam1.mp4 overlay/cam2.mp4 overlay/cam3.mp4 overlay/cam4.mp4)
for f in "${expected[@]}"; do
  [ -s "$out/command_result/$f" ] || fail "the --command run did not write $f; see $out/command.log"
done
run_in python3 -c 'import numpy; z = numpy.load("/mnt/out/command_result/joints.npz"); f = list(z["frames"]); assert f == [0, 1, 2], f' \
  || fail "joints.npz of the --command run does not hold frames 0-2"
grep -q "^Frames: 3" "$out/command_result/animation.bvh" || fail "animation.bvh does not hold 3 frames"
# the default landmark model (heavy) is what the installed extension tracked with
python3 -c 'import json, sys; m = json.load(open(sys.argv[1]))["settings"]["landmarks"]; assert m == "heavy", m' \
  "$out/command_result/report.json" || fail "the --command run did not track with the default heavy landmark model"
# the same files as the Python-module command (bpy 5.0.1 in .venv)
"$venv_py" -m markerless_mocap "${track_args[@]/$src/$repo}" --scene "$repo/sample_scenes/walk/subject.blend" --out "$out/module_result" > "$out/module.log" 2>&1 \
  || fail "python -m markerless_mocap track failed; see $out/module.log"
diff <(cd "$out/command_result" && find . -type f | sort) <(cd "$out/module_result" && find . -type f | sort) \
  > "$out/files.diff" || fail "--command and python -m wrote different files; see $out/files.diff"
log "--command run wrote every result file: ${expected[*]} (the same set as python -m markerless_mocap track)"

# 4c. a take sent to local processes from the Track panel (Run On: Local Processes), keyed when the batch ends: one
# actor in chunks (walk), then several actors as one take (duet), each keyed on its own armature
cluster_take() {  # SCENE: the sample scene whose subject.blend opens and whose capture is sent
  local t1
  t1=$(date +%s)
  run_in blender -b "$src/sample_scenes/$1/subject.blend" --python-exit-code 1 \
    --python "$src/tests/real_blender/cluster_take.py" -- "$src/sample_scenes/$1" "/mnt/out/cluster_$1" \
    > "$out/cluster_$1.log" 2>&1 || fail "$1 sent to local processes from the Track panel failed; see $out/cluster_$1.log"
  grep '^STAGE cluster' "$out/cluster_$1.log" | sed 's/^STAGE/[stage]/'
  log "$1 on local processes took $(( $(date +%s) - t1 )) s"
}
cluster_take walk
cluster_take duet

# 5. the UI under Xvfb: Import, Check, Track (the calibration first, modal; then tracking, modal), Esc, Resume twice, Export, with screenshots
start_xvfb
log "UI on Xvfb :$display: Import, Check, Track (the actor's fit, then tracking), Esc, Resume, Resume at 3 Hz, Export; two actors"
t1=$(date +%s)
drive_ui 420 /mnt/out/ui > "$out/ui.log" 2>&1 || fail "the UI run exited with $?; see $out/ui.log"
# several actors: the Track button (modal) with 'Track Every Armature' on the duet scene's two armatures
timeout 480 chroot "$root" /usr/bin/env DISPLAY=":$display" BLENDER_USER_RESOURCES=/mnt/out/blender_user \
  PYTHONDONTWRITEBYTECODE=1 NUMBA_CACHE_DIR=/var/cache/mocap-numba MOCAP_CACHE_DIR=/var/cache/mocap-motion \
  blender "$src/sample_scenes/duet/subject.blend" --window-geometry 0 0 1600 1200 \
  --python "$src/tests/real_blender/two_actors.py" -- "$src/sample_scenes/duet" /mnt/out/two_actors \
  > "$out/two_actors.log" 2>&1 || fail "the two-actor UI run exited with $?; see $out/two_actors.log"
kill "$xvfb_pid" 2>/dev/null || true
grep '^STAGE two' "$out/two_actors.log" | sed 's/^STAGE/[stage]/'
grep -q '^STAGE two actors.*: keyed both' "$out/two_actors.log" \
  || fail "tracking two actors from the Track panel (modal) failed; see $out/two_actors.log"
log "UI run took $(( $(date +%s) - t1 )) s"
grep '^STAGE-UI' "$out/ui.log" | sed 's/^STAGE-UI/[stage-ui]/'
# a panel's draw that raises only prints its traceback: the sidebar would show half a panel
grep -q Traceback "$out/ui.log" && fail "the UI run printed a traceback (a panel's draw?); see $out/ui.log"
python3 - "$out/ui/ui_report.json" <<'PY' || fail "the UI run did not do what a user does; see $out/ui.log and $out/ui/"
import json, os, re, sys
r = json.load(open(sys.argv[1]))
problems = list(r["errors"])
check = lambda ok, what: ok or problems.append(what)
check(r.get("sidebar_tab") == "Mocap", f"sidebar tab {r.get('sidebar_tab')!r}, not Mocap")
check(r.get("import", {}).get("result") == ["FINISHED"] and len(r["import"]["cameras"]) == 4, "Import Capture")
check(r.get("check", {}).get("dofs") == 30, "Check rig: 30 DOF")
check(r.get("preset") == {"name": "preview", "budget": [50, 4], "local_fit_fine": False},
      f"the Preview preset: {r.get('preset')}")
tracked = os.path.join(os.path.dirname(sys.argv[1]), "ui_result", "report.json")
model = json.load(open(tracked))["settings"]["landmarks"] if os.path.isfile(tracked) else None
check(model == "full", f"the Preview preset with the Landmark Model Auto tracked with {model!r}, not full")
cal = r.get("calibrate", {})
check(cal.get("track_click") == ["FINISHED"] and cal.get("invoke") == ["RUNNING_MODAL"],
      f"Track did not start the actor's calibration (modal): {cal.get('track_click')} {cal.get('invoke')}")
check(bool(cal.get("summary")) and cal["summary"][0].startswith("height 1.550 m (rig ")
      and cal["summary"][0].endswith("measured 1.550 m") and cal.get("use_actor"),
      f"no calibrated height (the measured 1.550 m) shown: {cal.get('summary')} {cal.get('error')!r}")
check(any(l.startswith("forearm 25.0 cm (rig ") and l.endswith(" as measured") for l in cal.get("summary", [])),
      f"no measured forearm (25.0 cm) shown: {cal.get('summary')}")
check(any(l.startswith("Calibrating: frame ") for l in cal.get("status_lines", [])), "no calibration progress line")
check(cal.get("ticks", 0) >= 5, f"the UI timer ticked {cal.get('ticks')} times while calibrating")
check(r.get("track_invoke") == ["RUNNING_MODAL"], "Track did not start (modal) once the calibration was saved")
cancel = r.get("cancel", {})
check(cancel.get("status", "").startswith("Cancelled after"), f"cancel status {cancel.get('status')!r}")
check(len(cancel.get("keyed_frames", [])) >= 2 and cancel.get("keyed_frames") == list(range(1, 1 + cancel.get("frames_solved", -1))),
      f"keys after the cancel: {cancel.get('keyed_frames')} for {cancel.get('frames_solved')} frames")
check(cancel.get("frames_solved", 99) < 30, "Esc did not stop the run")
k = cancel.get("frames_solved", -1)
resumed, again = r.get("resume", {}), r.get("resmooth", {})
check(resumed.get("invoke") == ["RUNNING_MODAL"] and resumed.get("status", "").startswith("Tracked 2 frames,")
      and resumed.get("keyed_frames") == list(range(1, k + 3)),
      f"Resume for two more frames: {resumed.get('status')!r}, keys {resumed.get('keyed_frames')} after {k} {resumed.get('error')!r}")
check(again.get("status") == f"All {k + 2} frames were already tracked; the take smoothed again at 3 Hz"
      and again.get("keyed_frames") == list(range(1, k + 3)),
      f"Resume of the finished take with Smoothing 3 Hz: {again.get('status')!r}, keys {again.get('keyed_frames')} {again.get('error')!r}")
lines = r.get("status_lines", [])
# The status is sampled by the UI timer, so at preview speed (0.3 s/frame) a given frame's line may be skipped:
# any frame after the first with its rate and time left will do.
check(any(re.match(r"Frame ([2-9]|[12][0-9]|30) of 30, [0-9.]+ s/frame, about .* left$", l) for l in lines),
      "no per-frame status line")
check(not any(" - " in l for l in lines if l.startswith("Frame ")), "a message stuck to a frame's status line")
check(r.get("max_ui_gap_s") is not None and r["max_ui_gap_s"] < 5, f"UI stalled {r.get('max_ui_gap_s')} s while tracking")
e = r.get("export", {})
check(e.get("fbx") == ["FINISHED"] and e.get("bvh") == ["FINISHED"] and e.get("fbx_bytes", 0) > 0 and e.get("bvh_bytes", 0) > 0, "Export")
check(len(r.get("screenshots", [])) == 7, f"screenshots: {r.get('screenshots')}")
if problems:
    print("\n".join("[stage-ui] FAILED: " + p for p in problems)); sys.exit(1)
print(f"[stage-ui] passed: calibrated in {cal.get('seconds')} s ({cal['summary'][0]}), {len(lines)} status lines, {r['timer_ticks_while_tracking']} UI timer ticks while tracking "
      f"(longest gap {r['max_ui_gap_s']} s), cancelled with {len(cancel['keyed_frames'])} frames keyed, "
      f"resumed to {len(resumed['keyed_frames'])}, smoothed again: '{again['status']}', screenshots in ui/")
PY
log "real-Blender stage PASSED in $(( $(date +%s) - t0 )) s (logs and screenshots: $out)"
