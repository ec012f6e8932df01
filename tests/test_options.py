"""One source for the tracking options (core/tracking/options.py): the Track panel's enum items, the command line's
choices and defaults and the engine's registries are the same lists, and the panel and the command line turn the
same choices into the same TrackingSettings (the panel used to drop `background`)."""
import argparse
import importlib

import numpy as np
import pytest

from markerless_mocap.core import optimizers, render
from markerless_mocap.core.energy.likelihood import LIKELIHOODS
from markerless_mocap.core.evidence.background import BackgroundModel
from markerless_mocap.core.tracking import options
from markerless_mocap.core.tracking.settings import PRESETS, TrackingSettings
from markerless_mocap.operators import cmd_track
from markerless_mocap.operators.cli import build_parser

ENUMS = ("algorithm", "likelihood", "preset", "refine", "backend", "background")


def _cli_actions(command="track"):
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return {a.dest: a for a in sub.choices[command]._actions}


def test_the_options_are_the_engines_registries_in_order():
    values = {name: options.OPTIONS[name].values for name in ENUMS}
    assert values["algorithm"] == tuple(optimizers.available_optimizers())
    assert values["likelihood"] == tuple(LIKELIHOODS)
    assert values["preset"] == tuple(PRESETS)
    assert values["backend"] == tuple(render.BACKENDS)
    defaults = {name: o.default for name, o in options.OPTIONS.items()}
    plain = TrackingSettings()
    chosen_by_preset = ("preset", "landmarks")  # "auto": the preset's model
    assert {k: v for k, v in defaults.items() if k not in chosen_by_preset} == {
        k: getattr(plain, k) for k in defaults if k not in chosen_by_preset}
    assert defaults["algorithm"] == optimizers.DEFAULT_OPTIMIZER
    assert TrackingSettings.preset(defaults["preset"]) == plain  # the default preset is the settings' defaults
    for option in options.OPTIONS.values():  # every value has words a person reads
        assert option.label and option.description
        assert all(c.label and c.description for c in option.choices)


@pytest.mark.parametrize("preset, chosen, used", [("full", "auto", "heavy"), ("preview", "auto", "full"),
                                                  ("preview", "heavy", "heavy"), ("full", "full", "full")])
def test_the_landmark_model_auto_is_the_presets(preset, chosen, used):
    """Preview's own model is full (heavy nearly doubles its time: docs/defaults.md, "landmarks"); a model chosen
    by name is used whatever the preset, on the command line as on the panel's mapping."""
    assert options.settings_from_choices({"preset": preset, "landmarks": chosen}).landmarks == used
    args = _cli_args({"preset": preset, "landmarks": chosen})
    assert cmd_track.settings_from_args(args).landmarks == used


@pytest.mark.parametrize("method", [v for v in options.OPTIONS["background"].values if v not in ("auto", "plate")])
def test_every_background_offered_is_one_the_engine_makes(method):
    """The background models are the one list core has no registry for: each clip-made one must build."""
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 255, (24, 32, 3), dtype=np.uint8) for _ in range(4)]
    assert BackgroundModel.from_frames(frames, method=method).silhouette(frames[0]).shape == (24, 32)


def test_an_optimiser_added_to_core_is_offered_without_retyping_it(monkeypatch):
    monkeypatch.setitem(optimizers._REGISTRY, "newopt", "newopt")
    rebuilt = options._build_options()["algorithm"]
    assert rebuilt.values[-1] == "newopt" and rebuilt.choices[-1].label == "NEWOPT"
    monkeypatch.setattr(cmd_track, "OPTIONS", options._build_options())
    parser = argparse.ArgumentParser()
    cmd_track.add_tracking_options(parser)
    assert parser.parse_args(["--algorithm", "newopt"]).algorithm == "newopt"


def test_the_command_line_offers_the_options_with_their_defaults():
    for command in ("track", "calibrate"):
        actions = _cli_actions(command)
        for name, option in options.OPTIONS.items():
            action = actions[name]
            if option.choices:
                assert tuple(action.choices) == option.values and action.default == option.default, (command, name)
            elif name in ("particles", "iterations"):
                assert action.default is None  # the preset's
            else:
                assert action.default == option.default


def test_a_value_the_engine_lacks_is_the_users_error():
    from markerless_mocap.core.errors import InputError

    with pytest.raises(InputError, match="background 'plates' is not one of auto, plate, median, mog2, knn"):
        options.settings_from_choices({"background": "plates"})
    with pytest.raises(TypeError):
        options.settings_from_choices({}, energy_scale=0.5)  # overrides are choices only
    without_background = argparse.Namespace(**{n: None for n in options.CHOICE_NAMES if n != "background"})
    with pytest.raises(AttributeError, match="background"):  # a side that forgets a choice is caught, not defaulted
        options.settings_from_choices(without_background)


CASES = [
    {},
    {"preset": "preview"},
    {"preset": "preview", "particles": 80, "background": "median"},
    {"algorithm": "apf", "likelihood": "silhch+color", "seed": 7, "refine": "none", "backend": "numpy",
     "background": "mog2", "iterations": 9},
    {"algorithm": "fsa", "likelihood": "silh+edge", "background": "plate", "backend": "fast"},
]


def _cli_args(case):
    argv = ["--capture", "c", "--out", "o"]
    for name, value in case.items():
        argv += [f"--{name}", str(value)]
    parser = argparse.ArgumentParser()
    cmd_track.add_arguments(parser)
    return parser.parse_args(argv)


@pytest.mark.bpy
def test_the_panel_offers_the_options_with_their_defaults(addon_module_name, bpy_module):
    bpy = bpy_module
    rna = bpy.context.scene.mocap.bl_rna.properties
    for name, option in options.OPTIONS.items():
        prop = rna[name]
        if name == "refine":  # a checkbox in the panel: ticked means "icp"
            assert prop.type == "BOOLEAN" and prop.default == (option.default == "icp")
        elif option.choices:
            assert tuple(item.identifier for item in prop.enum_items) == option.values, name
            assert tuple(item.name for item in prop.enum_items) == tuple(c.label for c in option.choices)
            assert prop.default == option.default, name
        else:
            assert prop.default == option.default, name
    prefs = bpy.context.preferences.addons[addon_module_name].preferences
    assert tuple(i.identifier for i in prefs.bl_rna.properties["default_backend"].enum_items) == tuple(render.BACKENDS)


@pytest.mark.bpy
@pytest.mark.parametrize("case", CASES)
def test_the_panel_and_the_command_line_give_the_same_settings(addon_module_name, bpy_module, case):
    bpy = bpy_module
    m = bpy.context.scene.mocap
    if "preset" in case:  # first: choosing a preset fills Particles / Iterations, as in the panel
        m.preset = case["preset"]
    for name, value in case.items():
        setattr(m, name, value == "icp" if name == "refine" else value)
    panel = m.tracking_settings().to_dict()
    cli = cmd_track.settings_from_args(_cli_args(case)).to_dict()
    assert panel == cli
    assert panel["background"] == case.get("background", "auto")
    # the Track operator's settings (the backend resolved) equal the command line's with that backend
    track = importlib.import_module(f"{addon_module_name}.operators.track")
    m.backend = "numpy"
    settings, choice = track.run_settings(bpy.context)
    assert choice.used == "numpy"
    assert settings.to_dict() == cmd_track.settings_from_args(_cli_args({**case, "backend": "numpy"})).to_dict()
