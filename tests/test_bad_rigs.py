"""Rigs that cannot be tracked: no skinned mesh, a mesh without weights, bones no preset maps, a rig
100x too large or too small. Each is refused in one line naming the object and the fix, by the rig
check in Blender and by the headless `track` (exit 2, no traceback)."""
import pytest

from rig_helpers import load_subject
from scene_helpers import scene_dir

bpy = pytest.importorskip("bpy")

from markerless_mocap.addon.scene_bridge import body_from_blender  # noqa: E402
from markerless_mocap.core.body.rig_checks import RigCheckError, require_person_height, standing_height  # noqa: E402
from markerless_mocap.core.body.rig_presets import RigMappingError  # noqa: E402
from markerless_mocap.operators.cli import main  # noqa: E402


def _scaled(factor):
    arm, mesh = load_subject(bpy)
    arm.scale = (factor,) * 3  # the mesh is deformed by the armature: it follows the armature object's scale
    mesh.scale = (factor,) * 3
    bpy.context.view_layer.update()
    return arm, mesh


def test_the_sample_subject_passes_at_its_height():
    arm, mesh = load_subject(bpy)
    body_from_blender(arm, mesh, bpy.context.scene)
    world = [mesh.matrix_world @ v.co for v in mesh.data.vertices]
    assert 1.5 < standing_height([tuple(v) for v in world]) < 2.0


@pytest.mark.parametrize("factor,words", [(100.0, "too large"), (0.01, "too small")])
def test_a_rig_100x_off_is_refused_naming_its_height(factor, words):
    arm, mesh = _scaled(factor)
    with pytest.raises(RigCheckError) as err:
        body_from_blender(arm, mesh, bpy.context.scene)
    text = str(err.value)
    assert f"stands {'1' if factor > 1 else '0.0'}" in text and words in text
    assert "apply the scale (Ctrl+A > Scale)" in text and "\n" not in text


def test_the_unit_scale_is_named_when_it_is_not_one():
    with pytest.raises(RigCheckError, match=r"set Scene > Units > Unit Scale to 1.0 \(it is 0.01\)"):
        require_person_height(175.0, "Performer", unit_scale=0.01)
    require_person_height(1.75, "Performer", unit_scale=0.01)  # a person's height in units passes


def test_a_mesh_without_weights_is_refused():
    arm, mesh = load_subject(bpy)
    every_vertex = list(range(len(mesh.data.vertices)))
    for group in mesh.vertex_groups:
        group.remove(every_vertex)
    with pytest.raises(RigCheckError) as err:
        body_from_blender(arm, mesh, bpy.context.scene)
    assert f"of {len(every_vertex)} vertices carry no weight" in str(err.value)
    assert "Ctrl+P > With Automatic Weights" in str(err.value)


def test_an_armature_without_a_skinned_mesh_is_refused():
    from markerless_mocap.addon.scene_bridge import SubjectError

    arm, mesh = load_subject(bpy)
    mesh.modifiers.remove(next(m for m in mesh.modifiers if m.type == "ARMATURE"))
    with pytest.raises(SubjectError, match="no mesh is skinned to armature .*add an Armature modifier"):
        body_from_blender(arm, None, bpy.context.scene)


def test_a_rig_that_cannot_be_mapped_is_refused_naming_the_bones():
    arm, mesh = load_subject(bpy)
    bone = next(b for b in arm.data.bones if "ForeArm" in b.name)
    old = bone.name
    bone.name = "Bone.017"
    with pytest.raises(RigMappingError, match=f"missing bones: .*{old}.*Rename these bones"):
        body_from_blender(arm, mesh, bpy.context.scene)


def test_track_refuses_a_scaled_rig_in_one_line(tmp_path, capsys):
    _scaled(100.0)
    scene_file = tmp_path / "giant.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(scene_file), copy=True)
    code = main(["track", "--scene", str(scene_file), "--capture", str(scene_dir("walk")), "--out",
                 str(tmp_path / "out"), "--frames", "0-1", "--no-export", "--no-overlays"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err[-1].startswith("markerless_mocap track: armature ") and "too large for a person" in err[-1]
    assert not any("Traceback" in line for line in err)
