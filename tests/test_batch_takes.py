"""The take list of `batch` (core/batch/takes.py, operators/cmd_batch.py): each bad input stops the batch before
anything is tracked, with a message that names the take and the fix; a good list reads with its settings."""
import pytest

from markerless_mocap.core.batch.takes import TakeListError, read_take_list

from scene_helpers import scene_dir

WALK = scene_dir("walk")  # 60 frames


def _toml(tmp_path, text):
    path = tmp_path / "takes.toml"
    path.write_text(text)
    return path


def _take(name="a", **keys):
    keys = {"scene": str(WALK / "subject.blend"), "capture": str(WALK), **keys}
    return f'[[take]]\nname = "{name}"\n' + "".join(f"{k} = {v if isinstance(v, int) else repr(v)}\n"
                                                    for k, v in keys.items())


def test_a_good_list_with_defaults_and_relative_paths(tmp_path):
    (tmp_path / "caps").mkdir()
    (tmp_path / "caps" / "walk").symlink_to(WALK, target_is_directory=True)
    path = _toml(tmp_path, '[defaults]\npreset = "preview"\nseed = 3\n'
                 + _take("one", capture="caps/walk", frames="0-29") + _take("two", capture="caps/walk",
                                                                           frames="30-59", seed=4))
    one, two = read_take_list(path, defaults={"particles": 20, "seed": 1})
    assert (one.name, one.frames, two.frames) == ("one", (0, 29), (30, 59))
    assert one.capture == tmp_path / "caps" / "walk"
    s1, s2 = one.settings(), two.settings()
    assert (s1.particles, s1.iterations, s1.seed, s2.seed) == (20, 4, 3, 4)  # line > [defaults] > command line


def test_a_take_of_several_actors_lists_their_armatures(tmp_path):
    one, two = read_take_list(_toml(tmp_path, _take("one", armature=["Lead"], frames="0-29")
                                    + _take("two", armature=["Lead", "Partner"], frames="30-59")))
    assert (one.armature, one.armatures, one.several) == ("Lead", (), False)
    assert (two.armature, two.armatures, two.several) == (None, ("Lead", "Partner"), True)


def test_every_frame_by_default(tmp_path):
    (take,) = read_take_list(_toml(tmp_path, _take()))
    assert take.frames == (0, 59)


@pytest.mark.parametrize("text,words", [
    (_take("a", capture="/nowhere/at/all"), "take 'a': capture /nowhere/at/all: .*does not exist"),
    (_take("a", frames="50-70"), "take 'a': frames 50-70, but capture .* has 60 frames"),
    (_take("a", frames="9-3"), "take 'a': frames 9-3: the last frame comes before the first"),
    (_take("a", frames="0-39") + _take("b", frames="30-59"),
     "take 'b': frames 30-59 overlap take 'a' \\(0-39\\) of the same capture"),
    (_take("a", colour="red"), "take 'a': unknown key colour"),
    (_take("a", preset="fastest"), "take 'a': preset 'fastest' is not one of"),
    (_take("a") + _take("a"), "take 'a': a second take of that name"),
    (_take("a/b"), "take 'a/b': take name 'a/b': use letters"),
    (_take("a", scene="/nowhere.blend"), "take 'a': scene /nowhere.blend: no such file"),
    (_take("a", actor="/nowhere/actor.json"), "take 'a': actor: .*no actor calibration there"),
    ('[[take]]\nname = "a"\nscene = "x.blend"\n', "take 'a': needs a capture"),
    ("[take]\nname = 1\n", "takes must be \\[\\[take\\]\\] tables"),
    ("[takes]\n", "unknown takes"),
    (_take("a", armature=["Lead", "Lead"]), "take 'a': armature \\['Lead', 'Lead'\\]: a name given twice"),
    (_take("a", armature=[]), "take 'a': armature must be the armature object's name \\(text\\), or a list"),
    (_take("a", measured="height=1.7"), "take 'a': measured must be a list of \"SEGMENT=METRES\" texts"),
    (_take("a", measured=["height=17"]), "take 'a': measured: --measured 'height=17': "),
    (_take("a", armature=["Lead", "Partner"], measured=["height=1.7"]), "take 'a': measured: .*say whose it is"),
    (_take("a", measured=["height=1.7"]) + "calibrate = false\n", "take 'a': measured lengths are for fitting the "
                                                                  "actor, but the take has calibrate = false"),
    (_take("a", armature=["Lead", "Partner"], actor="x.json"), "take 'a': actor is one actor's calibration, but "
                                                               "the take tracks Lead, Partner"),
])
def test_bad_inputs_name_the_take(tmp_path, text, words):
    with pytest.raises(TakeListError, match=words):
        read_take_list(_toml(tmp_path, text))


def test_a_folder_of_captures(tmp_path):
    (tmp_path / "walk").symlink_to(WALK, target_is_directory=True)
    (tmp_path / "notes").mkdir()  # no calibration: not a take
    (take,) = read_take_list(tmp_path)
    assert (take.name, take.scene, take.frames) == ("walk", tmp_path / "walk" / "subject.blend", (0, 59))
    # `batch --armature` names the armature(s) of the takes that do not name theirs: a folder's, or a list's
    (take,) = read_take_list(tmp_path, armature=["Lead", "Partner"])
    assert (take.armature, take.armatures) == (None, ("Lead", "Partner"))
    listed = _toml(tmp_path, _take("own", armature="Rig", frames="0-9")
                   + _take("named", frames="10-19", measured=["Partner:height=1.62"]))
    own, named = read_take_list(listed, armature=["Lead", "Partner"])
    assert (own.armature, own.armatures, named.armatures, named.measured) == (
        "Rig", (), ("Lead", "Partner"), ("Partner:height=1.62",))
    with pytest.raises(TakeListError, match="take 'named': measured: .*say whose it is"):
        read_take_list(_toml(tmp_path, _take("named", measured=["height=1.62"])), armature=["Lead", "Partner"])


def test_the_batch_refuses_a_subject_without_a_rig(bpy_module, tmp_path, capsys):
    from markerless_mocap.operators.cli import main

    bpy_module.ops.mesh.primitive_cube_add()
    empty = tmp_path / "cube.blend"
    bpy_module.ops.wm.save_as_mainfile(filepath=str(empty))
    path = _toml(tmp_path, _take("good", frames="10-59") + _take("cube", scene=str(empty), frames="0-9"))
    assert main(["batch", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "take 'cube': subject" in err and "armature" in err
    from markerless_mocap.core.batch.progress import read_progress

    progress = read_progress(tmp_path / "out")
    assert progress["state"] == "failed" and "take 'cube'" in progress["error"]


def test_the_panel_api_starts_a_batch_in_the_background_and_reads_its_end(tmp_path, monkeypatch):
    """launch_batch (what the Blender panel calls): a background process; its progress file says how it ended."""
    import time

    from markerless_mocap.core.batch.progress import read_progress
    from markerless_mocap.operators.cmd_batch import launch_batch
    from scene_helpers import cli_environment

    monkeypatch.setenv("PYTHONPATH", cli_environment()["PYTHONPATH"])
    proc = launch_batch([{"name": "lost", "scene": str(WALK / "subject.blend"), "capture": str(tmp_path / "gone")}],
                        tmp_path / "out")
    assert proc.wait(timeout=120) == 2
    progress = read_progress(tmp_path / "out")
    assert progress["state"] == "failed" and "take 'lost': capture" in progress["error"]
    assert "take 'lost'" in (tmp_path / "out" / "batch.log").read_text()
    assert time.time() - progress["updated"] < 120


@pytest.mark.parametrize("exit_code, runs", [(2, 1), (3, 2)])
def test_a_chunk_that_fails_for_the_users_reason_is_not_run_again(bpy_module, tmp_path, capsys, monkeypatch,
                                                                     exit_code, runs):
    """A chunk command that exits 2 (the footage, the rig, the settings: the same again would fail) fails its take
    at once with its own message; any other failure (a crash) is run again, up to --retries more times."""
    import sys

    from markerless_mocap.operators import cmd_batch
    from markerless_mocap.operators.cli import main

    counter = tmp_path / "runs.txt"
    script = (f"import sys; open({str(counter)!r}, 'a').write('run\\n'); "
              "print('markerless_mocap track-chunk: frame 3 of camera cam2 cannot be read', file=sys.stderr); "
              f"sys.exit({exit_code})")
    monkeypatch.setattr(cmd_batch.Batch, "chunk_argv", lambda self, run, chunk: [sys.executable, "-c", script])
    path = _toml(tmp_path, _take("short", frames="0-5"))
    code = main(["batch", str(path), "--out", str(tmp_path / "out"), "--workers", "1", "--retries", "1",
                 "--no-overlays", "--no-export"])
    assert code == 1
    err = capsys.readouterr().err
    assert "take 'short': chunk" in err and "frame 3 of camera cam2 cannot be read" in err
    assert counter.read_text().count("run") == runs


@pytest.mark.parametrize("text, words", [
    (_take("a", calibrate="yes"), "calibrate must be true or false"),
    (_take("a", actor="anna.json") + "calibrate = true\n", "calibrate and actor both given"),
])
def test_a_takes_calibration_key_is_checked(tmp_path, text, words):
    with pytest.raises(TakeListError, match=words):
        read_take_list(_toml(tmp_path, text))


def test_a_take_whose_actor_calibration_fails_fails_alone(bpy_module, tmp_path, capsys, monkeypatch):
    """`calibrate = true`: the take's actor is fitted before its chunks are planned; when the fit fails, that take
    fails with the calibration's own message and the other takes' chunks still run."""
    import sys

    from markerless_mocap.operators import cmd_batch
    from markerless_mocap.operators.cli import main

    counter = tmp_path / "chunks.txt"
    fail = ("import sys; print('markerless_mocap calibrate: no person found in frames 0-5', file=sys.stderr); "
            "sys.exit(2)")
    chunk = (f"import sys; open({str(counter)!r}, 'a').write(' '.join(sys.argv[1:]) + '\\n'); "
             "print('markerless_mocap track-chunk: stopped here by the test', file=sys.stderr); sys.exit(2)")
    monkeypatch.setattr(cmd_batch, "default_command", lambda: [sys.executable, "-c", fail])
    monkeypatch.setattr(cmd_batch.Batch, "chunk_argv",
                        lambda self, run, c: [sys.executable, "-c", chunk, run.take.name])
    path = _toml(tmp_path, _take("fitted", frames="0-5") + "calibrate = true\n" + _take("plain", frames="10-15"))
    assert main(["batch", str(path), "--out", str(tmp_path / "out"), "--workers", "1", "--no-overlays"]) == 1
    err = capsys.readouterr().err
    assert "take 'fitted': actor calibration: markerless_mocap calibrate: no person found in frames 0-5" in err
    assert counter.read_text().split() == ["plain"]  # the other take went on to its chunk


def test_takes_fit_their_actor_by_default_as_track_does(bpy_module, tmp_path, capsys, monkeypatch):
    """A take of at least 20 frames without an `actor` is fitted first (on its first 20 frames); a shorter take, a
    take with `calibrate = false`, and with `batch --no-calibrate` every take that does not ask for it, keep the
    rig."""
    import sys

    from markerless_mocap.operators import cmd_batch
    from markerless_mocap.operators.cli import main

    calls = tmp_path / "calibrations.txt"
    record = (f"import sys; a = sys.argv; open({str(calls)!r}, 'a').write(' '.join(a[a.index('--frames'):][:2] + "
              "[x for i, x in enumerate(a) if a[i - 1] == '--measured']) + '\\n'); "
              "print('markerless_mocap calibrate: stopped here by the test', file=sys.stderr); sys.exit(2)")
    chunk = "import sys; print('markerless_mocap track-chunk: stopped here by the test', file=sys.stderr); sys.exit(2)"
    monkeypatch.setattr(cmd_batch, "default_command", lambda: [sys.executable, "-c", record])
    monkeypatch.setattr(cmd_batch.Batch, "chunk_argv", lambda self, run, c: [sys.executable, "-c", chunk])
    path = _toml(tmp_path, _take("long", frames="0-19", armature="Armature", measured=["Armature:height=1.7",
                                                                                     "forearm=0.25"])
                 + _take("short", frames="20-38") + _take("off", frames="39-58") + "calibrate = false\n"
                 + _take("measured", frames="59-59", measured=["height=1.62"]))
    assert main(["batch", str(path), "--out", str(tmp_path / "out"), "--workers", "1", "--no-overlays"]) == 1
    # its measured lengths too; a short take is fitted when its actor was measured, as `track` fits it
    assert sorted(calls.read_text().splitlines()) == ["--frames 0-19 height=1.7 forearm=0.25",
                                                      "--frames 59-59 height=1.62"]
    err = capsys.readouterr().err
    assert "take 'long': actor calibration: markerless_mocap calibrate: stopped here by the test" in err
    calls.unlink()
    path = _toml(tmp_path, _take("long", frames="0-19") + _take("asked", frames="20-38") + "calibrate = true\n")
    assert main(["batch", str(path), "--out", str(tmp_path / "out2"), "--workers", "1", "--no-overlays",
                 "--no-calibrate"]) == 1
    assert calls.read_text().splitlines() == ["--frames 20-38"]  # only the take that asks


def test_a_fitted_actor_is_on_the_shared_storage_for_the_chunks_and_beside_the_result(bpy_module, tmp_path, capsys,
                                                                                      monkeypatch):
    """The fit is written under the chunks' folder (the workers' shared storage), the chunks track with it
    (--actor), the take's result folder keeps a copy (what Blender keys with), and a rerun fits nothing again."""
    import json
    import sys
    from pathlib import Path

    from markerless_mocap.operators import cmd_batch
    from markerless_mocap.operators.cli import main

    calls, chunks = tmp_path / "calibrations.txt", tmp_path / "chunks.txt"
    actor = {"format": "markerless_mocap.actor", "version": 1, "lengths_m": {"height": 1.7}, "factors": {}}
    fit = (f"import json, pathlib, sys; a = sys.argv; open({str(calls)!r}, 'a').write(a[a.index('--out') + 1] + "
           f"'\\n'); out = pathlib.Path(a[a.index('--out') + 1]); out.mkdir(parents=True, exist_ok=True); "
           f"(out / 'actor.json').write_text(json.dumps({actor!r}))")
    chunk = (f"import sys; a = sys.argv; open({str(chunks)!r}, 'a').write(a[a.index('--actor') + 1] + '\\n'); "
             "print('markerless_mocap track-chunk: stopped here by the test', file=sys.stderr); sys.exit(2)")
    monkeypatch.setattr(cmd_batch, "default_command", lambda: [sys.executable, "-c", fit])
    monkeypatch.setattr(cmd_batch.Batch, "chunk_argv", lambda self, run, c: [sys.executable, "-c", chunk,
                                                                           *self._take_args(run, str)])
    path = _toml(tmp_path, _take("long", frames="0-29") + _take("other", frames="30-59"))
    out = tmp_path / "out"
    for _ in range(2):
        assert main(["batch", str(path), "--out", str(out), "--workers", "2", "--no-overlays"]) == 1
    shared = [str((out / "_chunks" / name / "actor").resolve()) for name in ("long", "other")]
    assert sorted(calls.read_text().split()) == shared  # once each: the rerun reused the fits
    assert set(chunks.read_text().split()) == {str(Path(p) / "actor.json") for p in shared}
    for name in ("long", "other"):
        assert json.loads((out / name / "actor.json").read_text()) == actor
