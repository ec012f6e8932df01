"""Regenerate the sample capture folders (walk, playground) from the shared real data.

    .venv/bin/python sample_scenes/generate.py [--data ../shared/data] [--scene walk|playground|all]
                                              [--quick] [--samples N] [--no-render]

Deterministic: every random choice comes from a seeded generator per scene. This script (with
subject.py and stage.py next to it) is the only code that reads the shared data folder; the
product reads only what this writes under sample_scenes/.
"""
import argparse
import json
import math
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))      # the engine package `core` (bpy-free, relative imports inside)
sys.path.insert(0, str(HERE))

import bpy  # noqa: E402
import cv2  # noqa: E402

import stage  # noqa: E402
import subject  # noqa: E402
from core.capture.camera import BlenderCameraParams, Camera, camera_from_blender, camera_to_blender  # noqa: E402
from core.capture.calibration import write_easymocap_calibration, write_toml_calibration  # noqa: E402
from core.mocap import read_bvh, retarget  # noqa: E402
from core.actor.proportions import Proportions  # noqa: E402

W, H, FPS = 640, 480, 30

SCENES = {
    # start/n_frames in 30-fps frames of the resampled clip
    "walk": dict(bvh="131_01.bvh", start=128, n_frames=60, seed=131, uncontrolled=False, calibration="toml",
                 cameras=[  # azimuth deg, radius m, height m, fx px, (dcx, dcy) px, roll deg
                     (35, 3.7, 1.55, 540, (6.5, -4.0), 1.0),
                     (125, 3.3, 1.85, 520, (-5.0, 3.5), -1.5),
                     (215, 3.8, 1.30, 580, (3.0, 7.0), 0.5),
                     (300, 3.4, 1.70, 500, (-8.0, -2.5), -0.8)]),
    "playground": dict(bvh="01_01.bvh", start=580, n_frames=90, seed=101, uncontrolled=True, calibration="easymocap",
                       cameras=[
                           (40, 3.6, 1.60, 530, (4.0, -6.0), 0.8),
                           (130, 3.6, 1.35, 500, (-6.0, 2.0), -1.2),
                           (215, 3.7, 1.90, 560, (7.5, 5.0), 1.5),
                           (315, 3.6, 1.45, 510, (-3.5, -5.5), -0.4)]),
    # the hard scene of issue 13 (not tuned on): see docs/sample-scenes.md. Cameras stand on one side of
    # the subject's path (azimuths relative to the side facing away from the second person), so the second
    # person walks behind the subject in every view.
    "busy": dict(bvh="131_01.bvh", start=120, n_frames=80, seed=1313, uncontrolled=True, calibration="toml",
                 busy=True, noise=7.0, blur=0.7,
                 cameras=[
                     (-68, 3.9, 1.50, 520, (5.0, -3.0), 0.6),
                     (-22, 3.6, 1.75, 545, (-4.5, 6.0), -1.1),
                     (24, 3.7, 1.40, 505, (2.5, 4.5), 1.3),
                     (70, 3.9, 1.85, 560, (-7.0, -4.0), -0.5)],
                 # a second copy of the body: the same clip 12 frames later, walking the other way 1.9 m
                 # behind the subject's path, in other clothes
                 second=dict(bvh="131_01.bvh", start=132, offset_m=1.9,
                             colours={"shirt": (0.28, 0.09, 0.045), "trousers": (0.2, 0.16, 0.09),
                                      "hair": (0.12, 0.07, 0.03)}),
                 colours={"shirt": (0.15, 0.15, 0.14), "trousers": (0.055, 0.055, 0.055)},
                 # arm motion keyed on top of the walk: (first frame, frames in, frames held, frames out, targets)
                 gestures=[(6, 5, 8, 5, {"Right": "face"}),
                           (29, 6, 10, 5, {"Left": "cross", "Right": "cross_front"}),
                           (53, 5, 6, 4, {"Left": "face", "Right": "belly"}),
                           (70, 3, 2, 4, {"Right": "cross"})]),
    # held out (issue 13): nobody tunes on it; it judges whether a change tuned on the others generalises.
    # 01_01 turning round then a forward jump (source frames 272-331, playground's are 580-669), its own
    # gestures, a fourth camera layout, clothes and a second person of its own; busy's room and dimmer.
    "dusk": dict(bvh="01_01.bvh", start=272, n_frames=60, seed=2613, uncontrolled=True, calibration="easymocap",
                 busy=True, noise=6.0, blur=0.7,
                 cameras=[
                     (-84, 3.5, 1.25, 495, (-3.0, 5.5), -0.9),
                     (-37, 3.9, 1.95, 575, (6.0, 2.5), 1.4),
                     (9, 3.4, 1.60, 490, (-5.5, -6.5), 0.3),
                     (52, 3.8, 1.35, 550, (3.5, -1.5), -1.3)],
                 # another stretch of 01_01: jumps forward, the other way, 1.7 m behind the subject's path
                 second=dict(bvh="01_01.bvh", start=380, offset_m=1.7,
                             colours={"shirt": (0.04, 0.1, 0.05), "trousers": (0.3, 0.26, 0.18),
                                      "hair": (0.2, 0.17, 0.12)}),
                 colours={"shirt": (0.09, 0.11, 0.11), "trousers": (0.06, 0.05, 0.045)},
                 gestures=[(2, 8, 6, 6, {"Right": "overhead"}),
                           (23, 5, 6, 5, {"Left": "face", "Right": "face"}),
                           (39, 4, 5, 4, {"Left": "shoulder"}),
                           (50, 4, 3, 3, {"Right": "shoulder"})]),
    # held out like dusk, made on 2026-11-25 before any change of that day was measured: 01_01's forward
    # jumps just after the stretch dusk's second person uses (source frames 430-489), both arms crossed early, a
    # fifth camera layout (calibration.toml), clothes of its own and a second person; busy's room and dimmer.
    "lobby": dict(bvh="01_01.bvh", start=430, n_frames=60, seed=3717, uncontrolled=True, calibration="toml",
                  busy=True, noise=6.5, blur=0.7,
                  cameras=[
                      (-76, 3.6, 1.45, 510, (4.0, 3.5), 0.7),
                      (-31, 4.0, 1.80, 560, (-6.5, -2.0), -1.2),
                      (14, 3.5, 1.30, 525, (2.0, -5.5), 1.0),
                      (61, 3.7, 1.70, 540, (-3.0, 6.5), -0.6)],
                  second=dict(bvh="01_01.bvh", start=120, offset_m=1.8,
                              colours={"shirt": (0.05, 0.06, 0.18), "trousers": (0.12, 0.12, 0.12),
                                       "hair": (0.05, 0.04, 0.03)}),
                  colours={"shirt": (0.12, 0.12, 0.10), "trousers": (0.04, 0.045, 0.05)},
                  gestures=[(4, 6, 8, 5, {"Left": "cross", "Right": "cross"}),
                            (25, 5, 5, 4, {"Left": "face"}),
                            (39, 4, 6, 4, {"Right": "shoulder", "Left": "belly"}),
                            (53, 3, 2, 2, {"Left": "overhead"})]),
    # issue 15: the walk performed by an actor whose proportions differ from the subject the tracker is given
    # (8 % shorter overall, forearms 10 % longer than that); the tracker gets walk's subject.blend unchanged,
    # and the clip is placed so the actor starts where walk's subject was placed for.
    "actor": dict(bvh="131_01.bvh", start=128, n_frames=40, seed=1515, uncontrolled=False, calibration="toml",
                  cameras=[
                      (35, 3.7, 1.55, 540, (6.5, -4.0), 1.0),
                      (125, 3.3, 1.85, 520, (-5.0, 3.5), -1.5),
                      (215, 3.8, 1.30, 580, (3.0, 7.0), 0.5),
                      (300, 3.4, 1.70, 500, (-8.0, -2.5), -0.8)],
                  proportions=dict(overall=0.92, factors={"forearm": 0.92 * 1.10}), subject_from="walk"),
    # issue 15, held out: made on 2026-11-26 before anything was measured on it, after the calibration's last
    # change. Another build than the actor scene's, not a uniform scale: 5 % taller than the subject, with
    # (relative to that) shoulders 8 % and hips 6 % wider, a 4 % longer spine, 5 % shorter thighs and 6 %
    # shorter forearms; 131_01's stop and stand after the walk (source frames 200-239), walk's subject.blend
    # unchanged (busy's was turned 31 degrees from this clip's start: outside the placement promise), a camera
    # layout of its own, plates as on walk.
    "actor2": dict(bvh="131_01.bvh", start=200, n_frames=40, seed=2020, uncontrolled=False, calibration="toml",
                   cameras=[
                       (-20, 3.6, 1.65, 530, (-4.5, 5.0), -1.1),
                       (70, 3.9, 1.40, 565, (5.5, -3.0), 0.6),
                       (160, 3.5, 1.75, 505, (-2.5, -6.0), 1.3),
                       (250, 3.7, 1.35, 545, (7.0, 2.0), -0.4)],
                   proportions=dict(overall=1.05, factors={"shoulder_width": 1.05 * 1.08, "hip_width": 1.05 * 1.06,
                                                           "spine": 1.05 * 1.04, "thigh": 1.05 * 0.95,
                                                           "forearm": 1.05 * 0.94}),
                   subject_from="walk"),
    # issue 15, held out like actor2 (made on 2026-11-26, its baseline measured once): a third build, slight and
    # long-limbed: 3 % shorter overall than the subject, with (relative to that) a 12 % longer neck, shoulders
    # 7 % and hips 5 % narrower, a 4 % shorter spine, thighs 5 %, shins and upper arms 4 % longer; a forward
    # jump of 01_01 (source frames 80-119), playground's subject.blend unchanged (turned 15.5 degrees from the
    # actor's first facing), a camera layout of its own, plates.
    "actor3": dict(bvh="01_01.bvh", start=80, n_frames=40, seed=3030, uncontrolled=False, calibration="toml",
                   cameras=[
                       (15, 3.5, 1.50, 515, (3.5, -5.5), 0.9),
                       (100, 3.8, 1.80, 555, (-6.0, 2.5), -1.0),
                       (190, 3.6, 1.35, 535, (5.0, 4.0), 0.4),
                       (275, 3.9, 1.60, 570, (-2.0, -3.5), -1.4)],
                   proportions=dict(overall=0.97, factors={"neck": 0.97 * 1.12, "shoulder_width": 0.97 * 0.93,
                                                           "hip_width": 0.97 * 0.95, "spine": 0.97 * 0.96,
                                                           "thigh": 0.97 * 1.05, "shin": 0.97 * 1.04,
                                                           "upper_arm": 0.97 * 1.04}),
                   subject_from="playground"),
    # issue 15, held out (made on 2026-11-26 before anything was measured on it, to judge the calibration's
    # next change): a stocky build, long trunk on short legs, the opposite of actor3: 5 % shorter overall than the
    # subject, with (relative to that) a 6 % longer spine, 8 % shorter neck, shoulders 6 % and hips 3 % wider,
    # thighs 6 % and shins 4 % shorter, upper arms 3 % shorter and forearms 4 % longer; 131_01 before the walk
    # (source frames 16-55: standing, shuffling, turning 40 degrees), playground's subject.blend unchanged, five
    # cameras in a layout of its own, plates.
    "actor4": dict(bvh="131_01.bvh", start=16, n_frames=40, seed=4040, uncontrolled=False, calibration="toml",
                   cameras=[
                       (50, 3.4, 1.45, 525, (-3.5, 4.5), 0.7),
                       (120, 4.0, 1.90, 575, (4.0, -2.0), -1.2),
                       (195, 3.6, 1.55, 510, (-6.5, -3.5), 1.1),
                       (260, 3.8, 1.25, 560, (2.5, 6.0), -0.3),
                       (330, 3.5, 1.70, 540, (5.5, 1.5), 0.9)],
                   proportions=dict(overall=0.95, factors={"spine": 0.95 * 1.06, "neck": 0.95 * 0.92,
                                                           "shoulder_width": 0.95 * 1.06, "hip_width": 0.95 * 1.03,
                                                           "thigh": 0.95 * 0.94, "shin": 0.95 * 0.96,
                                                           "upper_arm": 0.95 * 0.97, "forearm": 0.95 * 1.04}),
                   subject_from="playground"),
    # issue 15, held out (made on 2026-11-26 after actor4's figures, before anything was measured on it, to judge
    # the choice among bodies between the rig and the calibration): tall and long-armed, 7 % taller overall than
    # the subject, with (relative to that) upper arms 5 % and forearms 6 % longer, hips 6 % narrower, a 2 % shorter
    # spine, thighs 3 % and shins 2 % longer; a forward jump of 01_01 (source frames 140-179: the hips rise 35 cm
    # and travel 0.9 m), playground's subject.blend unchanged, four cameras further out than elsewhere, plates.
    "actor5": dict(bvh="01_01.bvh", start=140, n_frames=40, seed=5050, uncontrolled=False, calibration="toml",
                   cameras=[
                       (-35, 4.3, 1.60, 545, (4.5, 3.0), -0.6),
                       (55, 4.6, 1.45, 580, (-3.0, -4.5), 1.2),
                       (145, 4.0, 1.95, 520, (6.0, 2.5), -0.9),
                       (230, 4.4, 1.35, 560, (-5.5, -1.0), 0.5)],
                   proportions=dict(overall=1.07, factors={"upper_arm": 1.07 * 1.05, "forearm": 1.07 * 1.06,
                                                           "hip_width": 1.07 * 0.94, "spine": 1.07 * 0.98,
                                                           "thigh": 1.07 * 1.03, "shin": 1.07 * 1.02}),
                   subject_from="playground"),
    # issue 15, held out (made on 2026-11-26 after actor5's figures, before anything was measured on it, to judge
    # the halfway body): 2 % shorter overall than the subject, with (relative to that) hips 6 % wider, shoulders
    # 5 % narrower, arms shorter (upper arm 5 %, forearm 4 %), a 3 % longer spine, 5 % longer neck, 3 % longer
    # shins and 4 % longer feet; 01_01 (source frames 30-69: standing with the hands at chest height, a deep
    # crouch, the take-off of a jump), playground's subject.blend unchanged, four cameras mounted high (2.1-2.4 m),
    # plates.
    "actor6": dict(bvh="01_01.bvh", start=30, n_frames=40, seed=6060, uncontrolled=False, calibration="toml",
                   cameras=[
                       (20, 3.6, 2.25, 530, (-4.0, 3.5), 0.8),
                       (110, 3.9, 2.40, 560, (3.5, -5.0), -1.1),
                       (200, 3.5, 2.10, 515, (5.0, 2.0), 0.4),
                       (290, 3.8, 2.30, 550, (-2.5, -4.0), -0.7)],
                   proportions=dict(overall=0.98, factors={"hip_width": 0.98 * 1.06, "shoulder_width": 0.98 * 0.95,
                                                           "upper_arm": 0.98 * 0.95, "forearm": 0.98 * 0.96,
                                                           "spine": 0.98 * 1.03, "neck": 0.98 * 1.05,
                                                           "shin": 0.98 * 1.03, "foot": 0.98 * 1.04}),
                   subject_from="playground"),
    # issue 15, held out (made on 2026-11-26 after actor6's figures, before anything was measured on it, to judge
    # the masks' choice of the trunk/leg split): 2 % taller overall than the subject, with (relative to that) a 5 %
    # shorter spine, 5 % shorter neck, thighs 5 % and shins 3 % longer, shoulders 4 % wider; 01_01 standing between
    # jumps (source frames 236-275, the hips within 3 cm), playground's subject.blend unchanged, four cameras of its
    # own, plates.
    "actor7": dict(bvh="01_01.bvh", start=236, n_frames=40, seed=7070, uncontrolled=False, calibration="toml",
                   cameras=[
                       (10, 3.7, 1.50, 535, (3.0, -4.5), -0.9),
                       (95, 3.4, 1.75, 515, (-5.5, 2.0), 1.0),
                       (185, 3.9, 1.40, 570, (4.5, 5.5), -0.2),
                       (265, 3.6, 1.65, 545, (-3.5, -2.0), 0.6)],
                   proportions=dict(overall=1.02, factors={"spine": 1.02 * 0.95, "neck": 1.02 * 0.95,
                                                           "thigh": 1.02 * 1.05, "shin": 1.02 * 1.03,
                                                           "shoulder_width": 1.02 * 1.04}),
                   subject_from="playground"),
    # issue 15, held out (made on 2026-11-26 before anything was measured on it, to judge how the masks set the
    # forearm): 6 % shorter overall than the subject, with (relative to that) forearms 9 % longer, upper arms
    # 4 % shorter, hips 4 % narrower, shins 3 % longer; 131_01 before the walk (source frames 52-91: standing,
    # shuffling, turning), playground's subject.blend unchanged, four cameras of its own, plates.
    "actor8": dict(bvh="131_01.bvh", start=52, n_frames=40, seed=8080, uncontrolled=False, calibration="toml",
                   cameras=[
                       (-5, 3.5, 1.60, 525, (-3.0, 4.0), 0.5),
                       (80, 3.8, 1.35, 560, (4.5, -3.5), -1.3),
                       (170, 3.6, 1.85, 540, (-5.0, -2.0), 0.9),
                       (245, 3.9, 1.45, 575, (2.0, 5.0), -0.4)],
                   proportions=dict(overall=0.94, factors={"forearm": 0.94 * 1.09, "upper_arm": 0.94 * 0.96,
                                                           "hip_width": 0.94 * 0.96, "shin": 0.94 * 1.03}),
                   subject_from="playground"),
    # issue 15, held out (made on 2026-11-26 before anything was measured on it): the first actor build in an
    # uncontrolled room (no plates, busy's clutter and changing light, a second person behind, sensor noise and
    # blur), where users' footage is. 4 % taller overall than the subject, with (relative to that) upper arms 6 %
    # longer, forearms 5 % shorter, shoulders 5 % narrower, a 6 % longer neck, thighs 4 % shorter, shins 3 % longer,
    # feet 5 % shorter; 01_01 just before playground's stretch (source frames 530-569: the end of a turn,
    # facing as playground's subject does) with its own gestures, playground's subject.blend unchanged,
    # EasyMocap calibration, four cameras of its own.
    "actor9": dict(bvh="01_01.bvh", start=530, n_frames=40, seed=9090, uncontrolled=True, calibration="easymocap",
                   busy=True, noise=6.0, blur=0.7,
                   cameras=[
                       (-80, 3.7, 1.55, 530, (3.5, -2.5), 0.8),
                       (-35, 3.5, 1.80, 550, (-4.0, 4.5), -1.0),
                       (12, 3.9, 1.40, 515, (5.0, 3.0), 0.5),
                       (58, 3.6, 1.65, 565, (-2.5, -5.0), -0.7)],
                   second=dict(bvh="01_01.bvh", start=640, offset_m=1.8,
                               colours={"shirt": (0.22, 0.2, 0.05), "trousers": (0.08, 0.1, 0.16),
                                        "hair": (0.1, 0.08, 0.05)}),
                   colours={"shirt": (0.1, 0.13, 0.09), "trousers": (0.05, 0.05, 0.06)},
                   gestures=[(5, 6, 7, 5, {"Right": "face"}),
                             (24, 5, 6, 4, {"Left": "shoulder", "Right": "overhead"})],
                   proportions=dict(overall=1.04, factors={"upper_arm": 1.04 * 1.06, "forearm": 1.04 * 0.95,
                                                           "shoulder_width": 1.04 * 0.95, "neck": 1.04 * 1.06,
                                                           "thigh": 1.04 * 0.96, "shin": 1.04 * 1.03,
                                                           "foot": 1.04 * 0.95}),
                   subject_from="playground"),
    # issue 15, held out (made on 2026-11-26 with actor9, before anything was measured on it): a studio build of
    # its own, 4 % shorter overall than the subject, with (relative to that) shoulders 6 % wider, upper arms 4 %
    # longer, forearms 4 % shorter, a 3 % shorter spine, thighs 3 % longer, feet 6 % longer; 01_01 between actor5's
    # and actor7's stretches (source frames 185-224), playground's subject.blend unchanged, plates.
    "actor10": dict(bvh="01_01.bvh", start=185, n_frames=40, seed=10100, uncontrolled=False, calibration="toml",
                    cameras=[
                        (30, 3.6, 1.70, 540, (-3.5, -3.0), 0.6),
                        (115, 3.8, 1.45, 520, (4.0, 5.0), -0.9),
                        (205, 3.5, 1.60, 560, (-5.0, 2.5), 1.2),
                        (285, 3.9, 1.85, 530, (2.5, -4.5), -0.5)],
                    proportions=dict(overall=0.96, factors={"shoulder_width": 0.96 * 1.06, "upper_arm": 0.96 * 1.04,
                                                            "forearm": 0.96 * 0.96, "spine": 0.96 * 0.97,
                                                            "thigh": 0.96 * 1.03, "foot": 0.96 * 1.06}),
                    subject_from="playground"),
    # issue 15, held out (made on 2026-11-27 before anything was measured on them): two more actor builds in
    # uncontrolled rooms like actor9's (no plates, busy's kind of clutter and changing light, a second person
    # behind, sensor noise and blur), to judge rules for such rooms on captures they were not read off.
    # actor11: 3 % shorter overall than the subject, with (relative to that) a 5 % longer spine, hips 6 % and
    # shoulders 3 % wider, thighs 5 % and neck 5 % shorter, forearms 4 % longer; 01_01 after dusk's stretch
    # (source frames 332-371, facing back the way lobby's subject faces), gestures of its own, a camera layout of
    # its own, calibration.toml; lobby's subject.blend unchanged (playground's faces the other way here).
    "actor11": dict(bvh="01_01.bvh", start=332, n_frames=40, seed=11110, uncontrolled=True, calibration="toml",
                    busy=True, noise=6.5, blur=0.7,
                    cameras=[
                        (-72, 3.8, 1.60, 525, (-4.0, 3.0), 0.9),
                        (-28, 3.5, 1.40, 505, (5.5, -4.0), -0.6),
                        (18, 3.9, 1.85, 570, (-2.5, 5.5), 1.1),
                        (64, 3.6, 1.50, 535, (4.5, -2.0), -1.2)],
                    second=dict(bvh="01_01.bvh", start=0, offset_m=1.8,
                                colours={"shirt": (0.3, 0.05, 0.07), "trousers": (0.1, 0.09, 0.08),
                                         "hair": (0.03, 0.025, 0.02)}),
                    colours={"shirt": (0.08, 0.09, 0.12), "trousers": (0.06, 0.055, 0.05)},
                    gestures=[(3, 5, 7, 5, {"Left": "face"}),
                              (22, 6, 6, 4, {"Right": "overhead", "Left": "belly"})],
                    proportions=dict(overall=0.97, factors={"spine": 0.97 * 1.05, "hip_width": 0.97 * 1.06,
                                                            "shoulder_width": 0.97 * 1.03, "thigh": 0.97 * 0.95,
                                                            "neck": 0.97 * 0.95, "forearm": 0.97 * 1.04}),
                    subject_from="lobby"),
    # actor12: 6 % taller overall than the subject, with (relative to that) hips 5 % narrower, shoulders 4 % wider,
    # upper arms 3 % shorter, shins 4 % and feet 4 % longer, a 2 % shorter spine; 01_01 right after actor11's
    # stretch (source frames 372-411, which dusk's second person walks), both arms crossed then a hand on the
    # shoulder, EasyMocap calibration, a second person walking 131_01, lobby's subject.blend unchanged.
    "actor12": dict(bvh="01_01.bvh", start=372, n_frames=40, seed=12120, uncontrolled=True, calibration="easymocap",
                    busy=True, noise=7.0, blur=0.8,
                    cameras=[
                        (-85, 3.6, 1.75, 550, (3.0, 4.5), -0.8),
                        (-40, 4.0, 1.35, 575, (-5.0, -3.5), 1.3),
                        (5, 3.5, 1.65, 500, (6.0, 2.0), -0.3),
                        (50, 3.8, 1.90, 545, (-3.5, -5.5), 0.7)],
                    second=dict(bvh="131_01.bvh", start=100, offset_m=1.9,
                                colours={"shirt": (0.2, 0.2, 0.22), "trousers": (0.03, 0.05, 0.12),
                                         "hair": (0.25, 0.2, 0.1)}),
                    colours={"shirt": (0.14, 0.1, 0.08), "trousers": (0.05, 0.06, 0.05)},
                    gestures=[(6, 5, 8, 5, {"Left": "cross", "Right": "cross"}),
                              (28, 4, 5, 3, {"Left": "shoulder"})],
                    proportions=dict(overall=1.06, factors={"hip_width": 1.06 * 0.95, "shoulder_width": 1.06 * 1.04,
                                                            "upper_arm": 1.06 * 0.97, "shin": 1.06 * 1.04,
                                                            "foot": 1.06 * 1.04, "spine": 1.06 * 0.98}),
                    subject_from="lobby"),
}
# issue 42 (other people in the room), rendered on 2026-11-27 before anything was tuned for it; never tune on it.
# The actor stands, turns round and stands again (01_01 source frames 244-303: the only clips at hand are the two
# the prior trains on). A second person dressed like the actor walks in (131_01 source frames 142-201: walking, then
# slowing to a stop), passes between the actor and cam1/cam2 (hips 0.45 m from the actor's at the closest) and stops
# beside it. Studio room (plates, constant light), so that the only difference from crossing_alone (the same scene
# without the second person: same seed, cameras, light, motion and subject.blend) is the second person. Cameras are
# placed by azimuth from the actor's first facing (the second person's path does not set them, unlike busy's).
CROSSING = dict(bvh="01_01.bvh", start=244, n_frames=60, seed=4242, uncontrolled=False, calibration="toml",
                cameras_from_facing=True,
                cameras=[
                    (5, 3.6, 1.60, 530, (4.5, -3.5), 0.7),
                    (58, 3.8, 1.75, 555, (-5.0, 4.0), -1.0),
                    (140, 3.5, 1.45, 515, (3.0, 6.0), 1.2),
                    (228, 3.7, 1.85, 545, (-6.5, -2.0), -0.5)],
                colours={"shirt": (0.09, 0.12, 0.17), "trousers": (0.03, 0.032, 0.04)})
SCENES["crossing"] = dict(
    CROSSING,
    # the walk is turned about its last hips, which stand `stop` (azimuth from the actor's first facing in degrees,
    # metres) from the actor's last hips, so that on its way it passes `pass_m` from the actor's hips at the closest,
    # on the side of the azimuth `pass_side_deg` (between the actor and cam1 and cam2)
    crossing=dict(bvh="131_01.bvh", start=142, stop=(92, 0.72), pass_m=0.45, pass_side_deg=45,
                  colours={"shirt": (0.1, 0.12, 0.155), "trousers": (0.035, 0.035, 0.042)}))
SCENES["crossing_alone"] = dict(CROSSING, subject_from="crossing")
# issue 42's DEVELOPMENT scene, rendered on 2026-11-27: meant to be tuned on (figures on it are never held-out
# results; the held-out crossing judges what is tuned here). The same idea as crossing, everything else other: the
# actor turns round in a few steps, stands, then crouches to jump, swinging the arms forward (01_01 source frames
# 490-549: apart from crossing's; no 60 frames of the clip avoid every other scene's, these share 20 with actor9's); a
# second person dressed like it walks 131_01 from source frame 150 (walking, then stopping), passes between it and
# cam1, then cam2 (hips 0.47 m from the actor's at the closest), and stops beside it. Own seed, cameras and clothes;
# studio room with plates. crossing_dev_alone is the same take without the second person.
CROSSING_DEV = dict(bvh="01_01.bvh", start=490, n_frames=60, seed=4545, uncontrolled=False, calibration="toml",
                    cameras_from_facing=True,
                    cameras=[
                        (-25, 3.7, 1.70, 540, (-4.0, 5.0), -0.9),
                        (-55, 3.5, 1.50, 520, (5.5, -2.5), 1.1),
                        (70, 3.9, 1.80, 560, (-3.0, -6.0), 0.4),
                        (160, 3.6, 1.40, 505, (6.0, 3.0), -1.3)],
                    colours={"shirt": (0.05, 0.12, 0.115), "trousers": (0.065, 0.055, 0.045)})
SCENES["crossing_dev"] = dict(
    CROSSING_DEV,
    crossing=dict(bvh="131_01.bvh", start=150, stop=(-100, 0.78), pass_m=0.47, pass_side_deg=-45,
                  colours={"shirt": (0.06, 0.125, 0.11), "trousers": (0.06, 0.05, 0.045)}))
SCENES["crossing_dev_alone"] = dict(CROSSING_DEV, subject_from="crossing_dev")
# issue 42, several actors, rendered on 2026-11-27 before anything was tuned for it (held out): two tracked actors
# of different builds, each with its own armature in subject.blend (`Lead`, `Partner`: the standard character as
# in every scene) and its own ground truth. The Lead is crossing's actor (01_01 source frames 244-303, standing,
# turning round, standing) with actor2's build; the Partner walks 131_01 from source frame 156 (walking, then
# slowing to a stop at about clip frame 48) with actor3's build. Its walk is bent (`turn`: first clip frame, frames,
# degrees) so that it passes behind the Lead's back 0.67 m from its hips, between it and cam1 (then cam2), while the
# Lead turns round, and stops facing it at `stop` (azimuth from the Lead's last facing in degrees, metres from its
# last hips); then both right hands reach to meet midway (`handshake`) and hold. Its start (156, not crossing's 142)
# lets it stop before the handshake. Cameras by azimuth from the Lead's first facing, chosen so that each person
# hides the other in two views; studio room as crossing's.
SCENES["duet"] = dict(
    bvh="01_01.bvh", start=244, n_frames=60, seed=4343, uncontrolled=False, calibration="toml",
    cameras_from_facing=True,
    cameras=[
        (155, 3.7, 1.55, 535, (-4.0, 3.0), 0.8),
        (210, 3.6, 1.80, 550, (5.5, -2.5), -1.1),
        (345, 3.8, 1.40, 520, (-3.0, -5.0), 0.5),
        (40, 3.5, 1.70, 540, (6.0, 4.0), -0.7)],
    colours={"shirt": (0.2, 0.045, 0.03), "trousers": (0.03, 0.032, 0.04)},
    proportions=SCENES["actor2"]["proportions"], proportions_from="actor2", armature="Lead",
    partner=dict(name="Partner", bvh="131_01.bvh", start=156, stop=(20, 0.9), facing_offset_deg=0,
                 turn=(28, 18, 120), proportions=SCENES["actor3"]["proportions"], proportions_from="actor3",
                 colours={"shirt": (0.045, 0.12, 0.05), "trousers": (0.14, 0.11, 0.07), "hair": (0.1, 0.06, 0.03)}),
    handshake=dict(first_frame=45, frames_in=6, above_hips_m=0.18))
# issue 42's DEVELOPMENT scene for telling actors apart by their looks, rendered on 2026-12-06: meant to be tuned on
# (the held-out duet judges what is tuned here). The duet's idea with everything else other: the Lead walks
# crossing_dev's window of 01_01 (turning round in a few steps, standing, crouching) with actor4's build, the
# Partner walks 131_01 from source frame 150 with actor5's build, bent the other way so that it passes behind the
# Lead's back; no handshake. Clothes of different colours (a mustard shirt and a blue one); own seed and cameras.
SCENES["duet_dev"] = dict(
    bvh="01_01.bvh", start=490, n_frames=60, seed=4949, uncontrolled=False, calibration="toml",
    cameras_from_facing=True,
    cameras=[
        (200, 3.7, 1.60, 540, (4.0, -3.0), -0.8),
        (145, 3.6, 1.75, 545, (-5.0, 2.5), 1.0),
        (20, 3.8, 1.45, 525, (3.5, 5.0), -0.4),
        (315, 3.5, 1.65, 535, (-6.0, -4.0), 0.6)],
    colours={"shirt": (0.25, 0.17, 0.03), "trousers": (0.035, 0.035, 0.04)},
    proportions=SCENES["actor4"]["proportions"], proportions_from="actor4", armature="Lead",
    partner=dict(name="Partner", bvh="131_01.bvh", start=144, stop=(-60, 0.9), facing_offset_deg=0,
                 turn=(26, 18, -110), proportions=SCENES["actor5"]["proportions"], proportions_from="actor5",
                 colours={"shirt": (0.03, 0.06, 0.2), "trousers": (0.1, 0.1, 0.1), "hair": (0.05, 0.04, 0.03)}),
    handshake=dict(first_frame=60, frames_in=6, above_hips_m=0.18))
# issue 42's second DEVELOPMENT scene for several actors, rendered on 2026-12-06: the duet's handshake (which
# duet_dev lacks) with everything else other, so that the hands and arms of two actors who touch can be tuned
# without the held-out duet. The Lead stands before 131_01's walk (source frames 0-59) with actor6's build (narrow
# shoulders, short arms); the Partner walks 131_01 from source frame 166 with actor8's build (short, long forearms),
# slows to a stop in front of the Lead and they shake hands from frame 38. Unlike the duet the Partner hides the Lead
# in cam1 from the first frame (frames 0-13), then in cam4 (32-59); the Lead hides the Partner in cam2 (35-59).
SCENES["handshake_dev"] = dict(
    bvh="131_01.bvh", start=0, n_frames=60, seed=5151, uncontrolled=False, calibration="toml",
    cameras_from_facing=True,
    cameras=[
        (316, 3.9, 1.60, 530, (3.0, -4.0), 0.5),
        (176, 3.8, 1.50, 520, (-4.0, 3.0), -0.9),
        (81, 3.8, 1.75, 545, (5.0, 2.0), 0.7),
        (352, 3.6, 1.55, 520, (-3.0, -5.0), -0.5)],
    colours={"shirt": (0.04, 0.1, 0.14), "trousers": (0.12, 0.1, 0.07)},
    proportions=SCENES["actor6"]["proportions"], proportions_from="actor6", armature="Lead",
    partner=dict(name="Partner", bvh="131_01.bvh", start=166, stop=(-15, 0.85), facing_offset_deg=0,
                 turn=(16, 18, 100), proportions=SCENES["actor8"]["proportions"], proportions_from="actor8",
                 colours={"shirt": (0.2, 0.06, 0.03), "trousers": (0.03, 0.03, 0.035), "hair": (0.08, 0.05, 0.03)}),
    handshake=dict(first_frame=38, frames_in=6, above_hips_m=0.18))
# issue 44 (a shoot day on a cluster): a long uncontrolled take for chunked `batch` tracking and its wall time.
# 01_01 is the only clip long enough (688 frames at 30 fps): source frames 40-639 jump forward 3.3 m, turn round,
# jump back, turn round again and jump on; arm gestures keyed on top every 60-70 frames. Playground's kind of room
# (no plates, light drifting over the take) but low sensor noise, so that 600 frames stay small; no second person
# (it would double the render). The cameras stand 4.0-4.5 m from the middle of the path, two of them near its ends
# (the person comes within 2.3 m of them), with wider lenses than elsewhere, so every joint stays in every view.
# Its frames are kept under the scene folder until the videos are encoded: the render takes hours and resumes.
SCENES["long"] = dict(
    bvh="01_01.bvh", start=40, n_frames=600, seed=4444, uncontrolled=True, calibration="toml",
    noise=2.0, blur=0.5, resumable=True,
    cameras=[
        (20, 4.5, 1.65, 600, (4.0, -3.0), 0.6),
        (98, 4.0, 1.40, 440, (-5.0, 2.5), -0.9),
        (200, 4.3, 1.85, 540, (3.0, 5.0), 1.1),
        (282, 4.2, 1.50, 470, (-2.5, -4.5), -0.4)],
    colours={"shirt": (0.1, 0.12, 0.045), "trousers": (0.045, 0.04, 0.06)},
    gestures=[(18, 6, 10, 6, {"Right": "face"}),
              (85, 8, 12, 6, {"Left": "overhead"}),
              (150, 6, 14, 6, {"Left": "cross", "Right": "cross"}),
              (215, 5, 10, 5, {"Right": "shoulder"}),
              (285, 6, 12, 6, {"Left": "belly", "Right": "face"}),
              (350, 8, 10, 6, {"Right": "overhead", "Left": "shoulder"}),
              (420, 5, 12, 5, {"Left": "face"}),
              (490, 6, 10, 6, {"Right": "belly"}),
              (555, 6, 12, 6, {"Left": "overhead", "Right": "overhead"})])
# issue 43 (hard motion), rendered on 2026-11-27 before anything was measured or tuned on it (held out): a person
# sits down on a low stool and pulls the knees up, poses no walking or jumping clip has (hips at 51 % of their
# standing height, thighs 30 degrees above horizontal). CMU 13_05 (subject 13 is kept out of the prior), an excerpt
# of source frames ~152-571 at 120 fps in motion/ (SOURCE.txt). The floor is set by the standing frames (the feet end
# up on the stool's step), a stool stands under the seated hips (in the plates too); four cameras of its own, the
# rig's build, plates, constant light.
SCENES["sit"] = dict(
    bvh="13_05_excerpt.bvh", start=0, n_frames=100, seed=4646, uncontrolled=False, calibration="toml",
    floor_frames=(0, 8), seat=dict(seated=(45, 100), below_hips_m=0.09),
    cameras=[
        (30, 3.6, 1.70, 535, (-3.5, 4.0), 0.7),
        (110, 3.4, 1.30, 510, (5.0, -2.5), -1.0),
        (200, 3.8, 1.85, 560, (-4.5, -5.0), 0.4),
        (285, 3.5, 1.45, 525, (3.0, 5.5), -0.8)],
    colours={"shirt": (0.16, 0.07, 0.12), "trousers": (0.04, 0.05, 0.08)})
# issue 43 (hard motion), rendered on 2026-11-27 before anything was measured or tuned on it (held out): expressive
# dance with only three cameras, an actor built unlike the character, in busy's kind of room. CMU 05_19 (modern
# dance; subject 05 is kept out of the prior), an excerpt of source frames 165-584 at 120 fps in motion/
# (SOURCE.txt): arm swings up to 7 m/s, a leg raised above hip height while standing on the other, a turning jump,
# the hips turning 383 degrees in all. The actor is 4 % taller than the subject, with (relative to that) shoulders 6 %
# wider, forearms 5 % longer, thighs 4 % shorter, a 2 % longer spine and a 5 % shorter neck; subject.blend is the
# standard character placed on the actor. Three cameras on the side away from a second person walking 1.4 m behind.
SCENES["dance"] = dict(
    bvh="05_19_excerpt.bvh", start=0, n_frames=100, seed=4747, uncontrolled=True, calibration="toml",
    busy=True, noise=6.5, blur=0.7,
    cameras=[
        (-62, 4.0, 1.55, 500, (4.0, -3.5), 0.8),
        (4, 4.2, 1.80, 520, (-5.0, 4.5), -1.0),
        (66, 3.9, 1.40, 490, (3.0, 5.0), 0.5)],
    second=dict(bvh="131_01.bvh", start=60, offset_m=1.4,
                colours={"shirt": (0.06, 0.09, 0.2), "trousers": (0.15, 0.13, 0.1), "hair": (0.08, 0.05, 0.03)}),
    colours={"shirt": (0.13, 0.12, 0.11), "trousers": (0.05, 0.045, 0.05)},
    proportions=dict(overall=1.04, factors={"shoulder_width": 1.04 * 1.06, "forearm": 1.04 * 1.05,
                                            "thigh": 1.04 * 0.96, "spine": 1.04 * 1.02, "neck": 1.04 * 0.95}))
# issue 43 (hard motion), a development scene for fast turns (dance is held out; rendered on 2026-12-07 before
# anything was tuned on it): 01_01's half turn (source frames 255-285) made a fast spin by a further 150 degrees
# over 14 frames on top of it (`turn`: first clip frame, frames, degrees; the hips turn up to 24 degrees a
# frame, a little faster than dance's turning jump), fast arm gestures, three cameras, an actor 3 %
# shorter than the subject with (relative to that) shoulders 5 % wider, forearms 5 % longer, thighs 4 % shorter and
# a 6 % shorter neck, in busy's kind of room without the second person.
SCENES["spin_dev"] = dict(
    bvh="01_01.bvh", start=236, n_frames=80, seed=5151, uncontrolled=True, calibration="toml",
    busy=True, noise=6.5, blur=0.7, turn=(34, 14, -150),
    cameras=[
        (-58, 4.0, 1.60, 505, (-3.0, 4.0), -0.7),
        (8, 4.1, 1.75, 515, (4.5, -3.5), 0.9),
        (70, 3.9, 1.45, 495, (-2.5, -5.0), -0.4)],
    gestures=[(8, 4, 6, 4, {"Right": "overhead"}),
              (26, 4, 8, 4, {"Left": "overhead", "Right": "shoulder"}),
              (52, 4, 6, 4, {"Left": "face"}),
              (64, 3, 6, 4, {"Right": "overhead"})],
    colours={"shirt": (0.12, 0.11, 0.1), "trousers": (0.05, 0.05, 0.045)},
    proportions=dict(overall=0.97, factors={"shoulder_width": 0.97 * 1.05, "forearm": 0.97 * 1.05,
                                            "thigh": 0.97 * 0.96, "neck": 0.97 * 0.94}))
# issue 43 (hard motion), held out (rendered on 2026-12-07 before anything was measured on it, to judge what
# spin_dev led to): 01_01's second half turn (source frames 490-520) made a fast spin by a further 150 degrees over
# 14 frames (the hips turn up to about 23 degrees a frame), arm gestures on top, three cameras of its own, an actor
# 3.5 % taller than the subject with (relative to that) shoulders 4 % narrower, upper arms and shins 4 % longer,
# hips 4 % wider, thighs and spine 2 % shorter, in busy's kind of room without the second person.
SCENES["spin"] = dict(
    bvh="01_01.bvh", start=466, n_frames=80, seed=5252, uncontrolled=True, calibration="toml",
    busy=True, noise=6.0, blur=0.7, turn=(24, 14, 150),
    cameras=[
        (-40, 3.9, 1.50, 500, (3.5, 3.0), 0.5),
        (35, 4.2, 1.85, 525, (-4.0, -2.5), -0.8),
        (110, 4.0, 1.40, 490, (2.0, 4.5), 1.0)],
    gestures=[(4, 4, 8, 4, {"Left": "overhead"}),
              (38, 4, 6, 4, {"Right": "face", "Left": "shoulder"}),
              (58, 3, 8, 4, {"Right": "overhead", "Left": "belly"})],
    colours={"shirt": (0.11, 0.1, 0.1), "trousers": (0.06, 0.05, 0.05)},
    proportions=dict(overall=1.035, factors={"shoulder_width": 1.035 * 0.96, "upper_arm": 1.035 * 1.04,
                                             "shin": 1.035 * 1.04, "hip_width": 1.035 * 1.04,
                                             "thigh": 1.035 * 0.98, "spine": 1.035 * 0.98}))
# issue 43 (the actor's build by default), held out (rendered on 2026-12-07 before anything was measured on it, to
# judge the rule spin_dev led to: the rig is not kept where the landmarks and the masks both read another height):
# an actor 3 % shorter than the subject with nearly its proportions (relative to that, a 1 % longer spine and 2 %
# shorter forearms), 01_01's standing and first forward jump (source frames 100-159) with arm gestures, three
# cameras, busy's kind of room without the second person.
SCENES["short"] = dict(
    bvh="01_01.bvh", start=100, n_frames=60, seed=5353, uncontrolled=True, calibration="toml",
    busy=True, noise=6.5, blur=0.7,
    cameras=[
        (-75, 4.1, 1.65, 510, (2.5, -4.0), -0.6),
        (-5, 3.9, 1.45, 495, (-3.0, 3.5), 0.7),
        (60, 4.2, 1.80, 520, (4.0, 2.0), -1.0)],
    gestures=[(6, 5, 8, 5, {"Right": "face"}),
              (32, 4, 8, 5, {"Left": "overhead", "Right": "belly"})],
    colours={"shirt": (0.14, 0.13, 0.12), "trousers": (0.05, 0.05, 0.06)},
    proportions=dict(overall=0.97, factors={"spine": 0.97 * 1.01, "forearm": 0.97 * 0.98}))
MASK_FRAMES = 5


def log(*a):
    print(time.strftime("%H:%M:%S"), *a, flush=True)


# ---------------------------------------------------------------- cameras
def look_at_camera(name, centre, target, fx, dc, roll_deg):
    """OpenCV camera at `centre` looking at `target` (world Z up), slight roll about the axis."""
    z = np.asarray(target, float) - centre
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)                       # +y image down
    Rcw = np.stack([x, y, z])                # rows: camera axes in world
    a = math.radians(roll_deg)
    roll = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    R = roll @ Rcw
    t = -R @ centre
    K = np.array([[fx, 0.0, (W - 1) / 2 + dc[0]], [0.0, fx, (H - 1) / 2 + dc[1]], [0.0, 0.0, 1.0]])
    return Camera(name, K, np.zeros(5), R, t, W, H)


def make_cameras(spec, action_centre):
    cams = []
    for k, (az, rad, hgt, fx, dc, roll) in enumerate(spec):
        a = math.radians(az)
        c = np.array([action_centre[0] + rad * math.cos(a), action_centre[1] + rad * math.sin(a), hgt])
        target = np.array([action_centre[0], action_centre[1], 0.85])
        cams.append(look_at_camera(f"cam{k + 1}", c, target, fx, dc, roll))
    return cams


def add_blender_camera(cam):
    p = camera_to_blender(cam, sensor_width=36.0, sensor_fit="HORIZONTAL")
    data = bpy.data.cameras.new(cam.name)
    data.lens_unit = "MILLIMETERS"
    data.lens = p.lens
    data.sensor_width = p.sensor_width
    data.sensor_height = p.sensor_height
    data.sensor_fit = p.sensor_fit
    data.shift_x = p.shift_x
    data.shift_y = p.shift_y
    data.clip_start = 0.05
    data.clip_end = 50.0
    ob = bpy.data.objects.new(cam.name, data)
    bpy.context.scene.collection.objects.link(ob)
    from mathutils import Matrix
    ob.matrix_world = Matrix(p.matrix_world.tolist())
    return ob, p


def blender_camera_record(ob, scene):
    """The parameters Blender actually holds (read back from the objects, not the intent)."""
    d = ob.data
    return dict(name=ob.name, matrix_world=[list(r) for r in ob.matrix_world], lens=d.lens,
                sensor_width=d.sensor_width, sensor_height=d.sensor_height, sensor_fit=d.sensor_fit,
                shift_x=d.shift_x, shift_y=d.shift_y, resolution_x=scene.render.resolution_x,
                resolution_y=scene.render.resolution_y, resolution_percentage=scene.render.resolution_percentage,
                pixel_aspect_x=scene.render.pixel_aspect_x, pixel_aspect_y=scene.render.pixel_aspect_y)


# ---------------------------------------------------------------- motion
def rest_arrays(arm):
    names = [b.name for b in arm.data.bones]
    parents = np.array([names.index(b.parent.name) if b.parent else -1 for b in arm.data.bones])
    rest = np.array([np.array(b.matrix_local) for b in arm.data.bones])
    tails = np.array([np.array(b.tail_local) for b in arm.data.bones])
    return names, parents, rest, tails


def key_motion(arm, res, names):
    from mathutils import Matrix
    arm.animation_data_clear()
    root = [n for n, b in zip(names, arm.data.bones) if b.parent is None][0]
    for pb in arm.pose.bones:
        pb.rotation_mode = "QUATERNION"
    F = res.basis_rotations.shape[0]
    for f in range(F):
        for b, n in enumerate(names):
            pb = arm.pose.bones[n]
            pb.rotation_quaternion = Matrix(res.basis_rotations[f, b].tolist()).to_quaternion()
            pb.keyframe_insert("rotation_quaternion", frame=f + 1)
            if n == root:
                pb.location = res.root_location[f].tolist()
                pb.keyframe_insert("location", frame=f + 1)


def forward_kinematics(basis, root_loc, rest, parents):
    """Armature-space pose matrices from matrix_basis rotations (F, B, 3, 3) and the root's location,
    as Blender (and core.mocap.retarget) compose them."""
    F, B = basis.shape[:2]
    b4 = np.zeros((F, B, 4, 4))
    b4[..., :3, :3] = basis
    b4[..., 3, 3] = 1.0
    root = int(np.nonzero(np.asarray(parents) < 0)[0][0])
    b4[:, root, :3, 3] = root_loc
    pose = np.empty_like(b4)
    inv_rest = np.linalg.inv(rest)
    for b in range(B):
        p = parents[b]
        pose[:, b] = rest[b] @ b4[:, b] if p < 0 else pose[:, p] @ (inv_rest[p] @ rest[b]) @ b4[:, b]
    return pose


def _rotation_between(a, b):
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    v, c = np.cross(a, b), float(a @ b)
    if np.linalg.norm(v) < 1e-9:
        return np.eye(3)
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K / (1 + c)


def _unit(v):
    return v / np.linalg.norm(v)


def gesture_weights(gestures, F):
    """Per gesture, a smooth 0..1 weight per frame (smoothstep in, hold, smoothstep out)."""
    out = []
    for start, t_in, hold, t_out, targets in gestures:
        w = np.zeros(F)
        for f in range(F):
            x = f - start
            if 0 <= x < t_in:
                u = (x + 1) / t_in
            elif t_in <= x < t_in + hold:
                u = 1.0
            elif t_in + hold <= x < t_in + hold + t_out:
                u = 1.0 - (x - t_in - hold + 1) / (t_out + 1)
            else:
                u = 0.0
            w[f] = u * u * (3 - 2 * u)
        out.append((w, targets))
    return out


def add_arm_gestures(res, names, parents, rest, gestures, world=None):
    """Key hand-to-face, arms-crossed, overhead and hand-to-shoulder motion on top of the retargeted clip:
    per frame, each arm's wrist is moved (along a path bulging forward, so it does not go through the body)
    towards a target in the body's frame, and the shoulder and elbow are turned by two-bone IK. A target
    ("reach", (x, y, z)) is a point in the world instead (the armature object's matrix_world is `world`, identity
    if None): the wrist goes there. Changes res in place."""
    F = res.basis_rotations.shape[0]
    idx = {n: k for k, n in enumerate(names)}
    to_armature = np.linalg.inv(np.eye(4) if world is None else np.asarray(world, float))
    basis = res.basis_rotations.copy()
    pose = forward_kinematics(basis, res.root_location, rest, parents)
    for w, targets in gesture_weights(gestures, F):
        for f in np.nonzero(w > 0)[0]:
            for side, kind in targets.items():
                other = "Left" if side == "Right" else "Right"
                P = pose[f, :, :3, 3]
                hips, neck, head = P[idx["Hips"]], P[idx["Neck"]], P[idx["Head"]]
                up = _unit(neck - hips)
                lat = P[idx["LeftArm"]] - P[idx["RightArm"]]            # towards the person's left
                lat = _unit(lat - (lat @ up) * up)
                fwd = np.cross(lat, up)                                  # left x up = forward (Z up, right-handed)
                side_dir = lat if side == "Left" else -lat
                chest = hips + 0.62 * (neck - hips)
                if isinstance(kind, tuple) and kind[0] == "reach":   # a handshake: the elbow low and out
                    T = to_armature[:3, :3] @ np.asarray(kind[1], float) + to_armature[:3, 3]
                    pole = -up + 0.5 * side_dir - 0.2 * fwd
                elif kind == "face":
                    T = head - 0.03 * up + 0.13 * fwd + 0.03 * side_dir
                    pole = -up + 0.6 * side_dir - 0.2 * fwd
                elif kind == "cross":
                    T = chest - 0.13 * side_dir + 0.17 * fwd
                    pole = side_dir - 0.5 * up
                elif kind == "cross_front":
                    T = chest - 0.05 * up - 0.14 * side_dir + 0.25 * fwd
                    pole = side_dir - 0.4 * up
                elif kind == "overhead":
                    T = head + 0.55 * up + 0.05 * fwd + 0.12 * side_dir
                    pole = side_dir - 0.3 * fwd
                elif kind == "shoulder":   # the hand on the opposite shoulder
                    T = P[idx[f"{other}Arm"]] + 0.02 * up + 0.08 * fwd
                    pole = side_dir - 0.7 * up + 0.3 * fwd
                else:   # "belly": the hand across the front of the belly, to the other side
                    T = hips + 0.3 * (neck - hips) - 0.1 * side_dir + 0.2 * fwd
                    pole = side_dir - 0.8 * up
                a_up, a_fore, a_hand = idx[f"{side}Arm"], idx[f"{side}ForeArm"], idx[f"{side}Hand"]
                S, E, Wr = P[a_up], P[a_fore], P[a_hand]
                # path: from the walk's wrist to the target, bulging 12 cm forward on the way
                T = (1 - w[f]) * Wr + w[f] * T + 0.12 * math.sin(math.pi * w[f]) * fwd
                l1, l2 = np.linalg.norm(E - S), np.linalg.norm(Wr - E)
                d = min(np.linalg.norm(T - S), 0.98 * (l1 + l2))
                d = max(d, abs(l1 - l2) + 1e-3)
                u = _unit(T - S)
                a = (l1 * l1 + d * d - l2 * l2) / (2 * d)
                h = math.sqrt(max(l1 * l1 - a * a, 0.0))
                # the elbow turns from where the walk has it to the gesture's pole as the weight rises
                pole = _unit(pole - (pole @ u) * u)
                now = (E - S) - ((E - S) @ u) * u
                if np.linalg.norm(now) > 1e-6:
                    pole = (1 - w[f]) * _unit(now) + w[f] * pole
                    pole = pole - (pole @ u) * u
                E_new = S + a * u + h * _unit(pole)
                T = S + d * u
                # upper arm: shoulder -> new elbow; then forearm: elbow -> target wrist (world rotations)
                for b, end in ((a_up, None), (a_fore, T)):
                    P2 = pose[f, :, :3, 3]
                    if end is None:
                        R = _rotation_between(E - S, E_new - S)
                    else:
                        R = _rotation_between(P2[a_hand] - P2[a_fore], end - P2[a_fore])
                    O_new = R @ pose[f, b, :3, :3]
                    p = parents[b]
                    basis[f, b] = rest[b, :3, :3].T @ rest[p, :3, :3] @ pose[f, p, :3, :3].T @ O_new
                    pose[f:f + 1] = forward_kinematics(basis[f:f + 1], res.root_location[f:f + 1], rest, parents)
    res.basis_rotations = basis
    res.pose_matrices = pose
    return res


def evaluated_joints_and_floor(arm, body, names, F):
    """Bone heads in world (from Blender's evaluated pose) and the lowest mesh point, per frame."""
    scene = bpy.context.scene
    P = np.zeros((F, len(names), 3))
    low = np.zeros(F)
    for f in range(F):
        scene.frame_set(f + 1)
        dg = bpy.context.evaluated_depsgraph_get()
        M = np.array(arm.matrix_world)
        for j, n in enumerate(names):
            h = np.array(arm.pose.bones[n].head)
            P[f, j] = M[:3, :3] @ h + M[:3, 3]
        ev = body.evaluated_get(dg)
        me = ev.to_mesh()
        co = np.empty(len(me.vertices) * 3)
        me.vertices.foreach_get("co", co)
        Mb = np.array(ev.matrix_world)
        co = co.reshape(-1, 3) @ Mb[:3, :3].T + Mb[:3, 3]
        low[f] = co[:, 2].min()
        ev.to_mesh_clear()
    return P, low


def clip_path(data_dir, bvh):
    """A clip of the shared data folder, or an excerpt kept next to this script (motion/, with its SOURCE.txt)."""
    kept = HERE / "motion" / bvh
    return kept if kept.is_file() else Path(data_dir) / "cmu" / bvh


def retarget_scene(cfg, data_dir, arm, F, first_hips_xy=None):
    clip = read_bvh(clip_path(data_dir, cfg["bvh"])).resample(FPS)
    start = cfg["start"]
    if start + F > clip.n_frames:
        raise ValueError(f"{cfg['bvh']}: frames {start}..{start + F} exceed the clip ({clip.n_frames} at {FPS} fps)")
    clip = clip.subset(np.arange(start, start + F))
    names, parents, rest, tails = rest_arrays(arm)
    res = retarget(clip, rest, parents, names, target_tails=tails)
    # centre the action at the origin (horizontally), or start it at first_hips_xy
    root_xy = res.pose_matrices[:, names.index("Hips"), :2, 3]
    shift = -(root_xy.min(axis=0) + root_xy.max(axis=0)) / 2
    if first_hips_xy is not None:
        shift = np.asarray(first_hips_xy, float) - root_xy[0]
    res = retarget(clip, rest, parents, names, target_tails=tails, translation=(shift[0], shift[1], 0.0))
    return clip, res, names, parents, rest, tails, shift


def add_second_person(spec, data, data_dir, F, centre, d, n):
    """A second copy of the body in other clothes, driven by `spec`'s clip, walking along the subject's
    path direction reversed, `offset_m` behind it (+n side). Returns its joints (F, B, 3) and a record."""
    from mathutils import Matrix
    arm2, body2 = subject.build_subject(bpy, data, colours=spec.get("colours"))
    arm2.name, body2.name = "Person2", "Person2Body"
    clip2, res2, names, parents, rest, tails, _ = retarget_scene(dict(bvh=spec["bvh"], start=spec["start"]),
                                                                 data_dir, arm2, F)
    key_motion(arm2, res2, names)
    _, low2 = evaluated_joints_and_floor(arm2, body2, names, F)
    h2 = res2.pose_matrices[:, names.index("Hips"), :2, 3]
    d2 = _unit(h2[-1] - h2[0])
    ang = math.atan2(-d[1], -d[0]) - math.atan2(d2[1], d2[0])
    c, s_ = math.cos(ang), math.sin(ang)
    G = np.eye(4)
    G[:2, :2] = [[c, -s_], [s_, c]]
    mid2 = G[:2, :2] @ ((h2.min(axis=0) + h2.max(axis=0)) / 2)
    G[:2, 3] = np.asarray(centre) + spec["offset_m"] * np.asarray(n) - mid2
    G[2, 3] = -float(np.median(low2))
    arm2.matrix_world = Matrix(G.tolist())
    P2, low2 = evaluated_joints_and_floor(arm2, body2, names, F)
    return P2, dict(source=f"{spec['bvh']} frames {spec['start']}..{spec['start'] + F - 1} at {FPS} fps",
                    offset_behind_path_m=spec["offset_m"], armature_matrix_world=G.tolist(),
                    clothing_colours_linear_rgb=spec.get("colours"),
                    lowest_point_m=[float(low2.min()), float(low2.max())])


def second_person_visibility(cams, P, P2):
    """Per camera: the fraction of frames in which at least half of the second person's joints project
    inside the image, and the frames where its hips project inside the subject's joint box while
    further away (it passes behind the subject)."""
    out = {}
    for cam in cams:
        uv2, z2 = cam.project_with_depth(P2.reshape(-1, 3))
        uv2, z2 = uv2.reshape(P2.shape[0], -1, 2), z2.reshape(P2.shape[0], -1)
        inside = ((uv2[..., 0] >= 0) & (uv2[..., 0] < cam.width) & (uv2[..., 1] >= 0) & (uv2[..., 1] < cam.height)
                  & (z2 > 0))
        uv1, z1 = cam.project_with_depth(P.reshape(-1, 3))
        uv1, z1 = uv1.reshape(P.shape[0], -1, 2), z1.reshape(P.shape[0], -1)
        hip = 0   # Hips is the root, first in the rig's order
        lo, hi = uv1.min(axis=1), uv1.max(axis=1)
        over = ((uv2[:, hip] >= lo) & (uv2[:, hip] <= hi)).all(axis=1)
        behind = over & (z2[:, hip] > z1[:, hip])
        out[cam.name] = dict(in_view_fraction=float((inside.mean(axis=1) >= 0.5).mean()),
                             behind_subject_frames=int(behind.sum()),
                             in_front_of_subject_frames=int((over & ~behind).sum()),
                             depth_m=[float(z2[:, hip].min()), float(z2[:, hip].max())])
    return out


def add_crossing_person(spec, data, data_dir, F, P, names, facing_deg):
    """Issue 42's crossing: a second copy of the body, dressed like the subject, whose clip is turned about its last
    hips (placed `stop` = (azimuth from the subject's first facing, metres) from the subject's last hips) so that its
    hips pass `pass_m` from the subject's at the closest, on the `pass_side_deg` side. Returns its joints (F, B, 3),
    its body object and a record (distances measured on the joints Blender evaluates)."""
    from mathutils import Matrix
    arm2, body2 = subject.build_subject(bpy, data, colours=spec.get("colours"))
    arm2.name, body2.name = "Person2", "Person2Body"
    _, res2, names2, *_ = retarget_scene(dict(bvh=spec["bvh"], start=spec["start"]), data_dir, arm2, F)
    key_motion(arm2, res2, names2)
    _, low2 = evaluated_joints_and_floor(arm2, body2, names2, F)
    root = names.index("Hips")
    hips = P[:, root, :2]
    h2 = res2.pose_matrices[:, names2.index("Hips"), :2, 3]
    a = math.radians(facing_deg + spec["stop"][0])
    stop = hips[-1] + spec["stop"][1] * np.array([math.cos(a), math.sin(a)])
    side = facing_deg + spec["pass_side_deg"]
    best = None
    for ang in np.radians(np.arange(0.0, 360.0, 0.25)):
        c, s_ = math.cos(ang), math.sin(ang)
        Rz = np.array([[c, -s_], [s_, c]])
        rel = (h2 - h2[-1]) @ Rz.T + stop - hips
        dist = np.linalg.norm(rel, axis=1)
        k = int(dist.argmin())
        az = math.degrees(math.atan2(rel[k, 1], rel[k, 0]))
        if abs((az - side + 180) % 360 - 180) > 60:     # passing on the other side
            continue
        if best is None or abs(dist[k] - spec["pass_m"]) < best[0]:
            best = (abs(dist[k] - spec["pass_m"]), ang, Rz)
    if best is None or best[0] > 0.03:
        raise RuntimeError(f"no turn of the second person's walk passes {spec['pass_m']} m from the subject")
    G = np.eye(4)
    G[:2, :2] = best[2]
    G[:2, 3] = stop - best[2] @ h2[-1]
    G[2, 3] = -float(np.median(low2))
    arm2.matrix_world = Matrix(G.tolist())
    P2, low2 = evaluated_joints_and_floor(arm2, body2, names2, F)
    hip_d = np.linalg.norm(P2[:, root, :2] - hips, axis=1)
    joint_d = np.linalg.norm(P2[:, :, None] - P[:, None], axis=3).min(axis=(1, 2))
    speed = np.linalg.norm(np.diff(P2[:, root, :2], axis=0), axis=1) * FPS
    return P2, body2, dict(
        source=f"{spec['bvh']} frames {spec['start']}..{spec['start'] + F - 1} at {FPS} fps",
        note="dressed like the subject; not in gt_joints or gt_masks (gt_masks are the subject's whole silhouette, "
             "also where the second person hides it)",
        armature_matrix_world=G.tolist(), clothing_colours_linear_rgb=spec.get("colours"),
        closest_hips_m=float(hip_d.min()), closest_hips_frame=int(hip_d.argmin()),
        closest_joints_m=float(joint_d.min()), closest_joints_frame=int(joint_d.argmin()),
        last_frame_hips_m=float(hip_d[-1]), walking_speed_m_per_s=[float(speed.min()), float(speed.max())],
        last_10_frames_speed_m_per_s=float(speed[-10:].max()), last_frame_speed_m_per_s=float(speed[-1]),
        lowest_point_m=[float(low2.min()), float(low2.max())])


def root_yaw(pose_root, rest_root):
    """The facing azimuth (radians, world or armature frame) of a root pose matrix: the rest pose faces -Y."""
    f = pose_root[:3, :3] @ rest_root[:3, :3].T @ np.array([0.0, -1.0, 0.0])
    return math.atan2(f[1], f[0])


def turn_walk(res, names, parents, rest, first, frames, degrees):
    """Bend a walk: from clip frame `first`, over `frames` frames, the body turns `degrees` about the vertical
    (smoothstep) and its steps turn with it, so the path curves rather than the body pivoting in place.
    Changes res in place."""
    root = names.index("Hips")
    F = res.basis_rotations.shape[0]
    h = res.pose_matrices[:, root, :3, 3]
    u = np.clip((np.arange(F) - first + 1) / frames, 0.0, 1.0)
    theta = math.radians(degrees) * u * u * (3 - 2 * u)
    new_h = h.copy()
    inv_rest = np.linalg.inv(rest[root])
    for f in range(F):
        c, s_ = math.cos(theta[f]), math.sin(theta[f])
        Rz = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
        if f:
            new_h[f, :2] = new_h[f - 1, :2] + Rz[:2, :2] @ (h[f, :2] - h[f - 1, :2])
        A = np.eye(4)
        A[:3, :3] = Rz
        A[:3, 3] = new_h[f] - Rz @ h[f]
        B = inv_rest @ A @ res.pose_matrices[f, root]
        res.basis_rotations[f, root] = B[:3, :3]
        res.root_location[f] = B[:3, 3]
    res.pose_matrices = forward_kinematics(res.basis_rotations, res.root_location, rest, parents)
    return res


def partner_placement(spec, res2, names2, rest2, P, names, lead_last_yaw):
    """The partner's armature matrix (without its floor height): its last hips `stop` = (azimuth from the Lead's
    last facing in degrees, metres) from the Lead's last hips, facing them (plus `facing_offset_deg`)."""
    root, root2 = names.index("Hips"), names2.index("Hips")
    a = lead_last_yaw + math.radians(spec["stop"][0])
    stop = P[-1, root, :2] + spec["stop"][1] * np.array([math.cos(a), math.sin(a)])
    to_lead = P[-1, root, :2] - stop
    want = math.atan2(to_lead[1], to_lead[0]) + math.radians(spec.get("facing_offset_deg", 0.0))
    ang = want - root_yaw(res2.pose_matrices[-1, root2], rest2[root2])
    c, s_ = math.cos(ang), math.sin(ang)
    G = np.eye(4)
    G[:2, :2] = [[c, -s_], [s_, c]]
    G[:2, 3] = stop - G[:2, :2] @ res2.pose_matrices[-1, root2, :2, 3]
    return G


def add_partner(spec, subject_data, data_dir, F, P, names, lead_last_yaw):
    """Issue 42's second tracked actor: the standard body scaled to `spec`'s proportions, in its own clothes,
    walking `spec`'s clip bent by `turn` and placed by partner_placement. Returns its armature, body, retarget
    result (keyed), rig arrays, joints (F, B, 3, evaluated by Blender) and its body data."""
    from mathutils import Matrix
    data2 = subject.scaled_subject_data(subject_data, Proportions(**spec["proportions"]))
    arm2, body2 = subject.build_subject(bpy, data2, colours=spec.get("colours"))
    arm2.name, body2.name = spec["name"], spec["name"] + "Body"
    _, res2, names2, parents2, rest2, *_ = retarget_scene(dict(bvh=spec["bvh"], start=spec["start"]), data_dir,
                                                          arm2, F)
    if spec.get("turn"):
        turn_walk(res2, names2, parents2, rest2, *spec["turn"])
    key_motion(arm2, res2, names2)
    _, low2 = evaluated_joints_and_floor(arm2, body2, names2, F)
    G = partner_placement(spec, res2, names2, rest2, P, names, lead_last_yaw)
    G[2, 3] = -float(np.median(low2))
    arm2.matrix_world = Matrix(G.tolist())
    P2, _ = evaluated_joints_and_floor(arm2, body2, names2, F)
    return dict(arm=arm2, body=body2, res=res2, names=names2, parents=parents2, rest=rest2, G=G, P=P2, data=data2)


def add_duet(cfg, name, arm, body, res, names, parents, rest, subject_data, data_dir, F, P):
    """The duet's Partner (add_partner) and the handshake, keyed on both as a "reach" gesture of the right arm
    (add_arm_gestures) after the Lead's floor shift. Returns the Lead's joints again and the Partner: its objects,
    joints P, first-frame yaw (as build_scene's yaw0), and the records for scene_info.json."""
    spec, hs = cfg["partner"], cfg["handshake"]
    root = names.index("Hips")
    p = add_partner(spec, subject_data, data_dir, F, P, names, root_yaw(res.pose_matrices[-1, root], rest[root]))
    if p["names"] != names:
        raise RuntimeError("the two actors' rigs name their bones differently")
    hold = F - hs["first_frame"] - hs["frames_in"]
    if hold > 0:   # (a --quick run's 8 frames end before it)
        meet, lead_T, partner_T = handshake_targets(hs, P, p["P"], names, F)
        add_arm_gestures(res, names, parents, rest, [(hs["first_frame"], hs["frames_in"], hold, 0,
                                                       {"Right": ("reach", tuple(lead_T))})])
        key_motion(arm, res, names)
        P, _ = evaluated_joints_and_floor(arm, body, names, F)
        add_arm_gestures(p["res"], names, p["parents"], p["rest"], [(hs["first_frame"], hs["frames_in"], hold, 0,
                                                                     {"Right": ("reach", tuple(partner_T))})],
                         world=p["G"])
        key_motion(p["arm"], p["res"], names)
    P2, low2 = evaluated_joints_and_floor(p["arm"], p["body"], names, F)
    for who, Q, heads, M in (("Lead", P, res.head_positions(), np.eye(4)), ("Partner", P2, p["res"].head_positions(),
                                                                               p["G"])):
        err = np.abs(Q - (heads @ M[:3, :3].T + M[:3, 3])).max()
        if err > 1e-3:
            raise RuntimeError(f"[{name}] {who}: Blender's evaluated pose disagrees with the keyed one ({err:.4f} m)")
    i = {n: k for k, n in enumerate(names)}
    hips_d = np.linalg.norm(P2[:, root, :2] - P[:, root, :2], axis=1)
    before = min(hs["first_frame"], F)
    joint_d = np.linalg.norm(P2[:before, :, None] - P[:before, None], axis=3).min(axis=(1, 2))
    speed = np.linalg.norm(np.diff(P2[:, root, :2], axis=0), axis=1) * FPS
    moving = np.nonzero(speed >= 0.1)[0]
    wrists = np.linalg.norm(P2[:, i["RightHand"]] - P[:, i["RightHand"]], axis=1)
    facing = {}
    for who, Q, other, M, r, rst in (("Lead", P, P2, np.eye(4), res, rest), ("Partner", P2, P, p["G"], p["res"],
                                                                               p["rest"])):
        to_other = other[-1, root, :2] - Q[-1, root, :2]
        yaw = root_yaw(M @ r.pose_matrices[-1, root], rst[root])
        facing[who] = (math.degrees(yaw - math.atan2(to_other[1], to_other[0])) + 180) % 360 - 180
    p["P"] = P2
    p["name"] = spec["name"]
    p["yaw0"] = root_yaw(p["G"] @ p["res"].pose_matrices[0, root], p["rest"][root]) - math.atan2(-1.0, 0.0)
    p["info"] = dict(
        source=f"{spec['bvh']} frames {spec['start']}..{spec['start'] + F - 1} at {FPS} fps",
        note="a second tracked actor: its own build (the standard body scaled as proportions_from's actor), clothes, "
             f"armature in subject.blend and truth (gt_joints_{spec['name']}.npz, gt_masks_{spec['name']}/); its "
             "walk bent by `turn` (the body and its steps turned about the vertical, smoothstep) and placed so that "
             "it stops at `stop` facing the Lead",
        turn=dict(first_frame=spec["turn"][0], frames=spec["turn"][1], degrees=spec["turn"][2]),
        stop_azimuth_from_lead_last_facing_deg=spec["stop"][0], stop_distance_m=spec["stop"][1],
        armature_matrix_world=p["G"].tolist(),
        hips_distance_m=np.round(hips_d, 4).tolist(),
        closest_hips_m=float(hips_d.min()), closest_hips_frame=int(hips_d.argmin()),
        closest_joints_before_handshake_m=float(joint_d.min()),
        closest_joints_before_handshake_frame=int(joint_d.argmin()), last_frame_hips_m=float(hips_d[-1]),
        walking_speed_m_per_s=[float(speed.min()), float(speed.max())],
        slower_than_0_1_m_per_s_from_frame=int(moving[-1] + 1) if len(moving) else 0,
        last_frame_speed_m_per_s=float(speed[-1]),
        last_frame_facing_off_the_other_deg=facing,
        lowest_point_m=[float(low2.min()), float(low2.max())])
    p["handshake"] = None
    log(f"[{name}] {spec['name']}: hips {hips_d.min():.3f} m from the Lead's at frame {hips_d.argmin()}, joints "
        f"{joint_d.min():.3f} m at frame {joint_d.argmin()} before the handshake, {hips_d[-1]:.3f} m at the last "
        f"frame; slower than 0.1 m/s from frame {p['info']['slower_than_0_1_m_per_s_from_frame']}; facing off the "
        f"other at the end: " + ", ".join(f"{k} {v:+.0f} deg" for k, v in facing.items()))
    if hold <= 0:
        return P, p
    held = np.arange(hs["first_frame"] + hs["frames_in"], F)
    miss = max(np.linalg.norm(P[held, i["RightHand"]] - lead_T, axis=1).max(),
               np.linalg.norm(P2[held, i["RightHand"]] - partner_T, axis=1).max())
    p["handshake"] = dict(
        note="both right hands reach (two-bone IK, smoothstep in) to meet midway between the right shoulders, "
             f"{hs['above_hips_m']} m above the mean hips height, each wrist a palm (0.06 m) short of the meeting "
             "point, and hold to the last frame; in both actors' ground truth",
        first_frame=hs["first_frame"], frames_in=hs["frames_in"], held_frames=[int(held[0]), int(held[-1])],
        meeting_point=meet.tolist(), wrist_targets={"Lead": lead_T.tolist(), "Partner": partner_T.tolist()},
        wrist_target_miss_when_held_m=float(miss), right_wrists_distance_m=np.round(wrists, 4).tolist(),
        hips_distance_when_held_m=[float(hips_d[held].min()), float(hips_d[held].max())])
    log(f"[{name}] handshake: frames {hs['first_frame']}-{F - 1} (held from {held[0]}), meeting point "
        f"{np.round(meet, 3).tolist()}, wrists {wrists[held].min():.3f}-{wrists[held].max():.3f} m apart when held, "
        f"targets missed by {miss * 1000:.1f} mm at most")
    return P, p


def add_seat(spec, P, names):
    """A stool under the seated hips: centred below the hips' mean position over the frames `seated`, its top
    `below_hips_m` under their lowest point (the hip joints sit above the buttocks). It stays in the plates."""
    a, b = spec["seated"]
    hips = P[a:b, names.index("Hips")]
    centre = hips[:, :2].mean(axis=0) + np.asarray(spec.get("shift_m", (0.0, 0.0)))
    top = float(hips[:, 2].min()) - spec["below_hips_m"]
    w = spec.get("width_m", 0.38)
    mat = stage.noisy(bpy, "stool", (0.16, 0.09, 0.04), (0.09, 0.05, 0.02), scale=6.0, kind="wave")
    stage.box(bpy, "Stool", (centre[0], centre[1], top / 2), (w, w, top), mat)
    return dict(top_m=top, centre_xy_m=centre.tolist(), width_m=w, seated_frames=[a, b])


def _frame_ranges(frames):
    """'3-9, 14-20' for the sorted frame numbers given."""
    out, start = [], None
    for k, f in enumerate(frames):
        if start is None:
            start = f
        if k + 1 == len(frames) or frames[k + 1] != f + 1:
            out.append(f"{start}-{f}" if f != start else f"{f}")
            start = None
    return ", ".join(out)


def handshake_targets(spec, P, P2, names, F):
    """Where each right wrist goes for the handshake: the hands meet midway between the two right shoulders
    (averaged over the held frames), `above_hips_m` over the mean hips height, each wrist a palm's length short
    of that point on its own side of the clasp."""
    i = {n: k for k, n in enumerate(names)}
    hold = np.arange(spec["first_frame"] + spec["frames_in"], F)
    meet = np.empty(3)
    meet[:2] = ((P[hold, i["RightArm"], :2] + P2[hold, i["RightArm"], :2]) / 2).mean(axis=0)
    meet[2] = ((P[hold, i["Hips"], 2] + P2[hold, i["Hips"], 2]) / 2).mean() + spec["above_hips_m"]
    u = np.zeros(3)
    u[:2] = _unit(P2[-1, i["Hips"], :2] - P[-1, i["Hips"], :2])
    left = np.array([-u[1], u[0], 0.0])          # the Lead's left
    palm, side = 0.06, 0.015
    return meet, meet - palm * u - side * left, meet + palm * u + side * left


def _hidden_fractions(dir_a, dir_b, cam_objs, cams, P, P2, frames):
    """Per camera and frame, the share of body a's mask (dir_a) that body b's (dir_b) covers while b's hips are
    nearer the camera."""
    out = {}
    for ob, cam in zip(cam_objs, cams):
        _, z1 = cam.project_with_depth(P[:, 0])
        _, z2 = cam.project_with_depth(P2[:, 0])
        frac = []
        for f in frames:
            a = cv2.imread(str(dir_a / ob.name / f"{f:04d}.png"), cv2.IMREAD_GRAYSCALE) > 0
            b = cv2.imread(str(dir_b / ob.name / f"{f:04d}.png"), cv2.IMREAD_GRAYSCALE) > 0
            frac.append(float((a & b).sum() / max(a.sum(), 1)) if z2[f] < z1[f] else 0.0)
        frac = np.array(frac)
        out[ob.name] = dict(hidden_fraction=np.round(frac, 3).tolist(), max_hidden=float(frac.max()),
                            frames_hidden_over_20_percent=int((frac > 0.2).sum()))
    return out


def overlap_by_second_person(cam_objs, body, body2, cams, P, P2, frames, both_ways=False):
    """Per camera and frame, the fraction of the subject's silhouette that the second person's covers while its
    hips are nearer the camera (Workbench masks of each body alone, every frame): where it hides the subject.
    both_ways: also the reverse (where the subject hides the second person), as a second dict."""
    tmp = Path(tempfile.mkdtemp(prefix="overlap_"))
    try:
        render_masks(cam_objs, body, tmp / "a", frames)
        render_masks(cam_objs, body2, tmp / "b", frames)
        out = _hidden_fractions(tmp / "a", tmp / "b", cam_objs, cams, P, P2, frames)
        if both_ways:
            return out, _hidden_fractions(tmp / "b", tmp / "a", cam_objs, cams, P2, P, frames)
        return out
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def hand_statistics(P, names, face_m=0.15):
    """How often a hand (wrist joint) is at the face (within face_m of the head joint) or in front
    of the torso past the body's midline (crossing it), from the ground-truth joints."""
    idx = {n: k for k, n in enumerate(names)}
    hips, neck = P[:, idx["Hips"]], P[:, idx["Neck"]]
    up = neck - hips
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    lat = P[:, idx["LeftArm"]] - P[:, idx["RightArm"]]
    lat -= (lat * up).sum(axis=1, keepdims=True) * up
    lat /= np.linalg.norm(lat, axis=1, keepdims=True)
    fwd = np.cross(lat, up)
    out = {}
    for side, sign in (("Left", 1.0), ("Right", -1.0)):
        h = P[:, idx[f"{side}Hand"]]
        rel = h - hips
        at_face = np.linalg.norm(h - P[:, idx["Head"]], axis=1) < face_m
        height = (rel * up).sum(axis=1)
        crossing = (sign * (rel * lat).sum(axis=1) < 0) & ((rel * fwd).sum(axis=1) > 0.05) & \
            (height > -0.05) & (height < np.linalg.norm(neck - hips, axis=1))
        out[f"{side.lower()}_hand_at_face_frames"] = int(at_face.sum())
        out[f"{side.lower()}_hand_across_torso_frames"] = int(crossing.sum())
    speed = np.linalg.norm(np.diff(P[:, [idx["LeftHand"], idx["RightHand"]]], axis=0), axis=2) * FPS
    out["max_hand_speed_m_per_s"] = float(speed.max())
    return out


# ---------------------------------------------------------------- rendering
def setup_cycles(samples, size):
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_adaptive_sampling = True
    scene.cycles.adaptive_threshold = 0.05
    scene.cycles.use_denoising = True
    try:
        scene.cycles.denoiser = "OPENIMAGEDENOISE"
        # measured on 2 shared cores: full-quality OIDN costs 3-4 s per 640x480 frame, FAST ~1 s
        scene.cycles.denoising_quality = "FAST"
        scene.cycles.denoising_prefilter = "NONE"
        scene.cycles.denoising_input_passes = "RGB"
    except (TypeError, AttributeError):
        pass
    scene.cycles.max_bounces = 3
    scene.cycles.diffuse_bounces = 2
    scene.cycles.glossy_bounces = 1
    scene.cycles.transmission_bounces = 1
    scene.cycles.transparent_max_bounces = 2
    scene.cycles.seed = 0
    scene.render.use_persistent_data = True
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    scene.render.fps = FPS
    scene.render.film_transparent = False
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGB"
    scene.view_settings.view_transform = "AgX"
    scene.view_settings.look = "AgX - Base Contrast"
    scene.view_settings.exposure = -0.6


def render_views(cam_objs, out_dir, frames):
    """Render every camera over `frames` into out_dir/<cam>/<frame:04d>.png. A frame whose image is already
    there and readable is kept, so a render that was stopped continues where it stopped."""
    scene = bpy.context.scene
    for ob in cam_objs:
        scene.camera = ob
        d = out_dir / ob.name
        d.mkdir(parents=True, exist_ok=True)
        # written beside the camera's folder and renamed when complete: a killed render leaves no half image
        # among the frames (encode_video reads every PNG in the folder)
        part = out_dir / f"{ob.name}.part.png"
        t0 = time.time()
        done = 0
        todo = [f for f in frames if not (d / f"{f:04d}.png").exists() or cv2.imread(str(d / f"{f:04d}.png")) is None]
        if len(todo) < len(frames):
            log(f"  {ob.name}: {len(frames) - len(todo)} of {len(frames)} frames already rendered, kept")
        for f in todo:
            scene.frame_set(f + 1)
            scene.render.filepath = str(part)
            bpy.ops.render.render(write_still=True)
            part.replace(d / f"{f:04d}.png")
            done += 1
            if done % 50 == 0 and done < len(todo):
                log(f"  {ob.name}: {done} of {len(todo)} frames, {(time.time() - t0) / done:.2f} s per frame")
        log(f"  {ob.name}: {done} frames in {time.time() - t0:.1f} s")


def resume_or_clear(frames_dir, settings):
    """A resumable scene's frame folder: kept if it was rendered with the same settings (scene, samples, size,
    frame count, cameras, scene configuration), emptied otherwise, so a changed scene never mixes frames."""
    stamp = frames_dir / "settings.json"
    text = json.dumps(settings, indent=1, sort_keys=True, default=str)
    if frames_dir.exists() and (not stamp.exists() or stamp.read_text() != text):
        log(f"  {frames_dir}: rendered with other settings, starting over")
        shutil.rmtree(frames_dir)
    frames_dir.mkdir(parents=True, exist_ok=True)
    stamp.write_text(text)


def post_process(img, rng, noise_sigma, blur_sigma):
    """Camera-like degradation: slight optical blur, then seeded Gaussian sensor noise."""
    out = img.astype(np.float32)
    if blur_sigma > 0:
        out = cv2.GaussianBlur(out, (0, 0), blur_sigma)
    if noise_sigma > 0:
        out += rng.normal(0.0, noise_sigma, out.shape).astype(np.float32)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def encode_video(frames_dir, path, rng, noise_sigma, blur_sigma):
    files = sorted(frames_dir.glob("*.png"))
    first = cv2.imread(str(files[0]))
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), FPS, (first.shape[1], first.shape[0]))
    if not vw.isOpened():
        raise RuntimeError(f"cv2.VideoWriter could not open {path}")
    for f in files:
        vw.write(post_process(cv2.imread(str(f)), rng, noise_sigma, blur_sigma))
    vw.release()


def render_masks(cam_objs, body, out_dir, frames):
    """Ground-truth silhouettes with Workbench: the body flat white, everything else hidden."""
    scene = bpy.context.scene
    saved = {ob.name: ob.hide_render for ob in scene.objects}
    for ob in scene.objects:
        if ob.type in ("MESH", "CURVE", "SURFACE", "META", "FONT") and ob != body:
            ob.hide_render = True
    scene.render.engine = "BLENDER_WORKBENCH"
    shading = scene.display.shading
    shading.light = "FLAT"
    shading.color_type = "SINGLE"
    shading.single_color = (1.0, 1.0, 1.0)
    shading.background_type = "VIEWPORT"
    shading.background_color = (0.0, 0.0, 0.0)
    scene.display.render_aa = "OFF"
    view = scene.view_settings.view_transform
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    exposure = scene.view_settings.exposure
    scene.view_settings.exposure = 0.0
    scene.render.film_transparent = False
    try:
        world_col = scene.world.color[:]
        scene.world.color = (0, 0, 0)
    except AttributeError:
        world_col = None
    tmp = Path(tempfile.mkdtemp(prefix="masks_"))
    for ob in cam_objs:
        scene.camera = ob
        d = out_dir / ob.name
        d.mkdir(parents=True, exist_ok=True)
        for f in frames:
            scene.frame_set(f + 1)
            scene.render.filepath = str(tmp / "m.png")
            bpy.ops.render.render(write_still=True)
            im = cv2.imread(str(tmp / "m.png"), cv2.IMREAD_GRAYSCALE)
            cv2.imwrite(str(d / f"{f:04d}.png"), np.where(im > 127, 255, 0).astype(np.uint8))
    shutil.rmtree(tmp, ignore_errors=True)
    for ob in scene.objects:
        ob.hide_render = saved.get(ob.name, False)
    scene.view_settings.view_transform = view
    scene.view_settings.exposure = exposure
    if world_col is not None:
        scene.world.color = world_col


# ---------------------------------------------------------------- subject.blend
def save_subject_blend(data, path, hips_world0, yaw0, rng, colours=None, offset=None, dyaw=None, fps=FPS,
                       floor_z=0.0, actors=()):
    """Armature + mesh in rest pose, placed where the person starts with a seeded error
    (or with the given horizontal offset in metres and yaw error in radians), soles at floor_z.
    actors: for several (the duet), one dict per actor: the first (this call's subject) gives its `name`, each
    further one dict(name, hips_world0, yaw0, colours) is placed the same way (its random draws after the
    first's). Each armature and its data are named after the actor, its mesh NAMEBody. Returns the first's
    placement, the others' in `others_placement`."""
    bpy.ops.wm.read_homefile(use_empty=True)
    arm, body = subject.build_subject(bpy, data, colours=colours)
    record = _place_subject(arm, hips_world0, yaw0, rng, offset, dyaw, floor_z)
    if actors:
        _name_subject(arm, body, actors[0]["name"])
        placed = {}
        for actor in actors[1:]:
            arm2, body2 = subject.build_subject(bpy, data, colours=actor.get("colours"))
            _name_subject(arm2, body2, actor["name"])
            placed[actor["name"]] = _place_subject(arm2, actor["hips_world0"], actor["yaw0"], rng, None, None,
                                                   floor_z)
        record["others_placement"] = placed
    bpy.context.scene.render.fps = int(round(fps))
    path.parent.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(path), compress=True)
    # The version-neutral source: this bpy's .blend does not open in older Blenders, so subject.blend is
    # rebuilt from it by the oldest Blender at hand (tests/real_blender/stage.sh --resave-subjects).
    sys.path.insert(0, str(REPO / "tools"))
    import portable_subject
    portable_subject.save_source(portable_subject.dump(), path.with_name("subject_source.json.gz"))
    return record


def _name_subject(arm, body, name):
    """An actor's armature (object and data) named `name`, its mesh NAMEBody, its materials NAME_region."""
    arm.name = arm.data.name = name
    body.name = body.data.name = f"{name}Body"
    for mat in body.data.materials:
        mat.name = f"{name}_{mat.name.split('.')[0].removeprefix('mocap_')}"


def _place_subject(arm, hips_world0, yaw0, rng, offset, dyaw, floor_z):
    from mathutils import Matrix
    if offset is None:
        ang = rng.uniform(0, 2 * np.pi)
        offset = 0.10 * np.array([math.cos(ang), math.sin(ang)])
    offset = np.asarray(offset, float)
    if dyaw is None:
        dyaw = math.radians(15.0) * (1 if rng.uniform() < 0.5 else -1)
    yaw = yaw0 + dyaw
    hips_rest = np.array(arm.data.bones["Hips"].head_local)
    c, s = math.cos(yaw), math.sin(yaw)
    Rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    M = np.eye(4)
    M[:3, :3] = Rz
    target = np.array([hips_world0[0] + offset[0], hips_world0[1] + offset[1], hips_rest[2] + floor_z])
    M[:3, 3] = target - Rz @ hips_rest
    arm.matrix_world = Matrix(M.tolist())
    return dict(offset_m=offset.tolist(), offset_norm_m=float(np.linalg.norm(offset)),
                yaw_error_deg=math.degrees(dyaw), armature_matrix_world=M.tolist())


def reuse_subject(source_dir, out, hips_world0, yaw0, hips_rest):
    """The tracker's subject is another scene's subject.blend unchanged (the actor differs from it, not the
    file); its placement error is measured against this scene's first frame."""
    for name in ("subject.blend", "subject_source.json.gz"):
        shutil.copy(source_dir / name, out / name)
    M = np.array(json.loads((source_dir / "scene_info.json").read_text())["subject_placement"]["armature_matrix_world"])
    hips = M[:3, :3] @ np.asarray(hips_rest, float) + M[:3, 3]
    offset = hips[:2] - np.asarray(hips_world0[:2], float)
    yaw = math.degrees(math.atan2(M[1, 0], M[0, 0]))
    return dict(copied_from=source_dir.name, offset_m=offset.tolist(), offset_norm_m=float(np.linalg.norm(offset)),
                yaw_error_deg=(yaw - math.degrees(yaw0) + 180) % 360 - 180, armature_matrix_world=M.tolist())


# ---------------------------------------------------------------- main
def build_scene(name, data_dir, out_root, samples, quick, render):
    cfg = SCENES[name]
    rng = np.random.default_rng(cfg["seed"])
    F = 8 if quick else cfg["n_frames"]
    out = out_root / name
    out.mkdir(parents=True, exist_ok=True)
    log(f"[{name}] building subject and motion ({F} frames)")
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    data = subject.load_subject_data(data_dir)
    first_hips_xy = None
    if cfg.get("proportions"):
        subject_data = data
        data = subject.scaled_subject_data(data, Proportions(**cfg["proportions"]))
        if cfg.get("subject_from"):
            first_hips_xy = json.loads((out_root / cfg["subject_from"] / "scene_info.json").read_text())[
                "first_frame_hips"][:2]
    arm, body = subject.build_subject(bpy, data, colours=cfg.get("colours"))
    if cfg.get("partner"):
        arm.name, body.name = cfg["armature"], cfg["armature"] + "Body"
    clip, res, names, parents, rest, tails, shift = retarget_scene(cfg, data_dir, arm, F, first_hips_xy)
    if cfg.get("turn"):   # a turn on top of the clip's own (the partner's `turn` bends its walk the same way)
        turn_walk(res, names, parents, rest, *cfg["turn"])
        yaw = np.unwrap([root_yaw(m, rest[names.index("Hips")]) for m in res.pose_matrices[:, names.index("Hips")]])
        log(f"[{name}] after the turn the hips turn up to {np.degrees(np.abs(np.diff(yaw))).max():.1f} deg per frame")
    if cfg.get("gestures"):
        add_arm_gestures(res, names, parents, rest, cfg["gestures"])
    key_motion(arm, res, names)
    scene.frame_start, scene.frame_end = 1, F
    P, low = evaluated_joints_and_floor(arm, body, names, F)
    # feet on the floor: the median lowest point (most frames have a foot down) goes to z = 0; over the
    # `floor_frames` only where the person later has the feet up (on a stool's step)
    a, b = cfg.get("floor_frames", (0, F))
    dz = float(np.median(low[a:b]))
    rootb = names.index("Hips")
    res.root_location = res.root_location - (rest[rootb, :3, :3].T @ np.array([0, 0, dz]))
    res.pose_matrices[..., 2, 3] -= dz
    key_motion(arm, res, names)
    P, low = evaluated_joints_and_floor(arm, body, names, F)
    err = np.abs(P - res.head_positions()).max()
    log(f"[{name}] floor shift {dz * 100:.1f} cm; lowest point per frame {low.min():.3f}..{low.max():.3f} m; "
        f"Blender pose vs retarget heads max diff {err * 1000:.3f} mm")
    if err > 1e-3:
        raise RuntimeError("Blender's evaluated pose disagrees with the retargeted pose matrices")

    # where the person is, for cameras and subject.blend
    hips = P[:, rootb]
    centre = (hips[:, :2].min(axis=0) + hips[:, :2].max(axis=0)) / 2
    cam_spec = cfg["cameras"]
    root_rot = res.pose_matrices[0, rootb, :3, :3] @ rest[rootb, :3, :3].T   # root rotation from rest
    fwd = root_rot @ np.array([0.0, -1.0, 0.0])                             # the rest pose faces -Y
    yaw0 = math.atan2(fwd[1], fwd[0]) - math.atan2(-1.0, 0.0)
    if cfg.get("cameras_from_facing"):   # azimuths from the way the subject faces at the first frame
        cam_spec = [(math.degrees(math.atan2(fwd[1], fwd[0])) + az, *rest_) for az, *rest_ in cam_spec]
    second_info = None
    body2 = None
    if cfg.get("crossing"):
        P2, body2, second_info = add_crossing_person(cfg["crossing"], data, data_dir, F, P, names,
                                                     math.degrees(math.atan2(fwd[1], fwd[0])))
        log(f"[{name}] second person: hips {second_info['closest_hips_m']:.3f} m from the subject's at frame "
            f"{second_info['closest_hips_frame']}, joints {second_info['closest_joints_m']:.3f} m at frame "
            f"{second_info['closest_joints_frame']}, {second_info['last_frame_hips_m']:.3f} m at the last frame")
    if cfg.get("second"):
        # cameras on the side of the path away from the second person (azimuths relative to that side)
        d = _unit(hips[-1, :2] - hips[0, :2])
        n = np.array([-d[1], d[0]])
        az0 = math.degrees(math.atan2(-n[1], -n[0]))
        cam_spec = [(az0 + az, *rest_) for az, *rest_ in cam_spec]
        P2, second_info = add_second_person(cfg["second"], data, data_dir, F, centre, d, n)
    partner = None
    if cfg.get("partner"):
        P, partner = add_duet(cfg, name, arm, body, res, names, parents, rest, subject_data, data_dir, F, P)
        P2, body2 = partner["P"], partner["body"]
    cams = make_cameras(cam_spec, centre)
    tracked = [("the subject", P)] if partner is None else [(cfg["armature"], P), (partner["name"], P2)]
    for cam in cams:
        for who, Q in tracked:   # every tracked actor's joints well inside every image
            uv, depth = cam.project_with_depth(Q.reshape(-1, 3))
            inside = (uv[:, 0] > 8) & (uv[:, 0] < W - 9) & (uv[:, 1] > 8) & (uv[:, 1] < H - 9) & (depth > 0)
            if not inside.all():
                msg = f"[{name}] {cam.name}: {np.count_nonzero(~inside)} joint projections of {who} leave the image"
                if quick and partner is not None and who == partner["name"]:
                    log(msg + " (a --quick run places the Partner by its 8 frames' end)")
                    continue
                raise RuntimeError(msg)
    if partner is not None:
        partner["info"]["views"] = second_person_visibility(cams, P, P2)
    if second_info is not None:
        second_info["views"] = second_person_visibility(cams, P, P2)
        log(f"[{name}] second person: " + "; ".join(
            f"{k}: in view {v['in_view_fraction']:.2f}, behind the subject {v['behind_subject_frames']} frames, "
            f"in front {v['in_front_of_subject_frames']}"
            for k, v in second_info["views"].items()))

    if cfg.get("seat"):
        info_seat = add_seat(cfg["seat"], P, names)
        log(f"[{name}] seat: top {info_seat['top_m']:.3f} m at {np.round(info_seat['centre_xy_m'], 3).tolist()}")
    moving = stage.build_room(bpy, rng, cfg["uncontrolled"], grey=cfg.get("busy", False))
    stage.animate_moving(bpy, moving, F)
    stage.build_lights(bpy, cfg["uncontrolled"], F, busy=cfg.get("busy", False))
    cam_objs = []
    records = []
    if quick:   # quarter size, with the calibration scaled to match
        cams = [c.scaled(0.25) for c in cams]
    setup_cycles(samples, cams[0].size)
    for cam in cams:
        ob, _ = add_blender_camera(cam)
        cam_objs.append(ob)
        records.append(blender_camera_record(ob, scene))
        # what Blender holds (float32 lens/shift) must still be the calibration
        r = records[-1]
        back = camera_from_blender(BlenderCameraParams(
            np.array(r["matrix_world"]), r["lens"], r["sensor_width"], r["sensor_height"], r["sensor_fit"],
            r["shift_x"], r["shift_y"], r["resolution_x"], r["resolution_y"], r["pixel_aspect_x"],
            r["pixel_aspect_y"], r["name"]))
        if np.abs(back.K - cam.K).max() > 1e-4 or np.abs(back.R - cam.R).max() > 1e-6:
            raise RuntimeError(f"{cam.name}: the Blender camera does not reproduce the calibration")
    (out / "render_cameras.json").write_text(json.dumps(
        {"note": "Blender camera objects exactly as rendered (created with core.capture.camera.camera_to_blender)",
         "cameras": records}, indent=1))
    for old in ("calibration.toml", "intri.yml", "extri.yml"):
        (out / old).unlink(missing_ok=True)
    if cfg["calibration"] == "toml":
        write_toml_calibration(cams, out / "calibration.toml")
    else:
        write_easymocap_calibration(cams, out)
    np.savez_compressed(out / "gt_joints.npz", names=np.array(names), frames=np.arange(F),
                        positions=P.astype(np.float64), fps=np.float64(FPS),
                        source=np.array(f"{cfg['bvh']} frames {cfg['start']}..{cfg['start'] + F - 1} at {FPS} fps"))
    if cfg.get("crossing"):   # the other person's joints, to tell a switch onto it from a plain error
        np.savez_compressed(out / "second_person_joints.npz", names=np.array(names), frames=np.arange(F),
                            positions=P2.astype(np.float64), fps=np.float64(FPS),
                            source=np.array(second_info["source"]))
    if partner is not None:   # every actor's truth, named after its armature (the Lead's is gt_joints.npz too)
        for who, Q, src in ((cfg["armature"], P, f"{cfg['bvh']} frames {cfg['start']}..{cfg['start'] + F - 1} at "
                                                 f"{FPS} fps"), (partner["name"], P2, partner["info"]["source"])):
            np.savez_compressed(out / f"gt_joints_{who}.npz", names=np.array(names), frames=np.arange(F),
                                positions=Q.astype(np.float64), fps=np.float64(FPS), source=np.array(src))
    mask_frames = np.linspace(0, F - 1, MASK_FRAMES).round().astype(int).tolist()
    shutil.rmtree(out / "gt_masks", ignore_errors=True)
    if render:
        if cfg.get("resumable"):   # kept until the videos are encoded: a stopped render resumes on the next run
            tmp = out / "_frames"
            resume_or_clear(tmp, dict(scene=name, samples=samples, quick=quick, n_frames=F, cameras=records,
                                      config=cfg))
        else:
            tmp = Path(tempfile.mkdtemp(prefix=f"render_{name}_"))
        finished = False
        try:
            log(f"[{name}] rendering {len(cams)} cameras x {F} frames, {samples} samples")
            render_views(cam_objs, tmp / "frames", list(range(F)))
            noise, blur = (4.0, 0.7) if cfg["uncontrolled"] else (1.5, 0.0)
            noise, blur = cfg.get("noise", noise), cfg.get("blur", blur)
            (out / "videos").mkdir(exist_ok=True)
            for k, ob in enumerate(cam_objs):
                encode_video(tmp / "frames" / ob.name, out / "videos" / f"{ob.name}.mp4",
                             np.random.default_rng([cfg["seed"], k]), noise, blur)
            if not cfg["uncontrolled"]:
                people = [b for b in (body, body2) if b is not None]
                for b in people:
                    b.hide_render = True
                render_views(cam_objs, tmp / "plates", [0])
                for b in people:
                    b.hide_render = False
                (out / "background").mkdir(exist_ok=True)
                for k, ob in enumerate(cam_objs):
                    img = cv2.imread(str(tmp / "plates" / ob.name / "0000.png"))
                    cv2.imwrite(str(out / "background" / f"{ob.name}.png"),
                                post_process(img, np.random.default_rng([cfg["seed"], 100 + k]), noise, blur))
            keep = tmp / "frames"
            (out / "preview").mkdir(exist_ok=True)
            for ob in cam_objs:
                shutil.copy(keep / ob.name / f"{mask_frames[2]:04d}.png", out / "preview" / f"{ob.name}.png")
            finished = True
        finally:
            if finished or not cfg.get("resumable"):   # a resumable scene keeps its frames until the videos are written
                shutil.rmtree(tmp, ignore_errors=True)
    render_masks(cam_objs, body, out / "gt_masks", mask_frames)
    if partner is not None:
        shutil.rmtree(out / f"gt_masks_{partner['name']}", ignore_errors=True)
        render_masks(cam_objs, body2, out / f"gt_masks_{partner['name']}", mask_frames)
        lead_hidden, partner_hidden = overlap_by_second_person(cam_objs, body, body2, cams, P, P2, list(range(F)),
                                                               both_ways=True)
        hidden = {f"{cfg['armature']}_hidden_by_{partner['name']}": lead_hidden,
                  f"{partner['name']}_hidden_by_{cfg['armature']}": partner_hidden}
        for k, v in hidden.items():
            log(f"[{name}] {k}: " + "; ".join(
                f"{c}: up to {h['max_hidden']:.2f}, > 20 % in {h['frames_hidden_over_20_percent']} frames"
                + (f" ({_frame_ranges(np.nonzero(np.array(h['hidden_fraction']) > 0.2)[0])})"
                   if h['frames_hidden_over_20_percent'] else "")
                for c, h in v.items()))
    if body2 is not None and cfg.get("crossing"):
        second_info["hidden_by_second_person"] = overlap_by_second_person(cam_objs, body, body2, cams, P, P2,
                                                                          list(range(F)))
        log(f"[{name}] the second person hides the subject: " + "; ".join(
            f"{k}: up to {v['max_hidden']:.2f}, > 20 % in {v['frames_hidden_over_20_percent']} frames"
            for k, v in second_info["hidden_by_second_person"].items()))
    # the full scene, for inspection (not committed)
    bpy.ops.wm.save_as_mainfile(filepath=str(Path(tempfile.gettempdir()) / f"mocap_scene_{name}.blend"))

    # subject.blend: rest pose, near the first frame's root, with a seeded placement error
    if cfg.get("subject_from"):
        placement = reuse_subject(out_root / cfg["subject_from"], out, hips[0], yaw0,
                                  (subject_data if cfg.get("proportions") else data)["bones"]["Hips"]["head"])
    elif partner is not None:   # both actors' armatures, the standard character, each placed on its own person
        placement = save_subject_blend(subject_data, out / "subject.blend", hips[0], yaw0, rng,
                                       colours=cfg.get("colours"), actors=[
                                           dict(name=cfg["armature"]),
                                           dict(name=partner["name"], hips_world0=P2[0, rootb], yaw0=partner["yaw0"],
                                                colours=cfg["partner"].get("colours"))])
        partner["placement"] = placement.pop("others_placement")[partner["name"]]
    elif cfg.get("proportions"):   # the standard character (not the actor's build), placed on the actor
        placement = save_subject_blend(subject_data, out / "subject.blend", hips[0], yaw0, rng,
                                       colours=cfg.get("colours"))
    else:
        placement = save_subject_blend(data, out / "subject.blend", hips[0], yaw0, rng, colours=cfg.get("colours"))
    info = dict(scene=name, source=cfg["bvh"], first_source_frame_30fps=cfg["start"], n_frames=F, fps=FPS,
                cameras=[c.name for c in cams], mask_frames=mask_frames, samples=samples, quick=quick,
                floor_shift_m=dz, trajectory_shift_m=np.asarray(shift).tolist(), root_scale=res.root_scale,
                first_frame_hips=hips[0].tolist(), first_frame_yaw_deg=math.degrees(yaw0),
                subject_placement=placement)
    if cfg.get("gestures"):
        info["arm_overlay"] = dict(
            note="arm motion keyed on top of the retargeted clip (two-bone IK towards targets in the body's "
                 "frame, blended in and out with smoothstep weights); the ground truth is Blender's evaluated pose",
            gestures=[dict(first_frame=g[0], frames_in=g[1], frames_held=g[2], frames_out=g[3], targets=g[4])
                      for g in cfg["gestures"]],
            **hand_statistics(P, names))
    if second_info is not None:
        info["second_person"] = second_info
    if cfg.get("seat"):
        info["seat"] = info_seat
    if cfg.get("colours"):
        info["clothing_colours_linear_rgb"] = cfg["colours"]
    if cfg.get("proportions"):
        info["actor"] = dict(
            note="the body rendered differs from subject.blend (the tracker's subject): the subject's segments "
                 "scaled by these factors (core.actor.proportions); gt_joints.npz are the actor's joints",
            proportions=cfg["proportions"],
            true_segment_lengths_m=subject.segment_lengths_of(data, rest, names),
            subject_segment_lengths_m=subject.segment_lengths_of(subject_data, rest, names))
    if partner is not None:
        lead, other = cfg["armature"], partner["name"]
        info["actors"] = {
            lead: dict(armature=lead, gt_joints=f"gt_joints_{lead}.npz", gt_masks="gt_masks",
                       source=info["source"] + f" frames {cfg['start']}..{cfg['start'] + F - 1} at {FPS} fps",
                       proportions_from=cfg.get("proportions_from"), proportions=cfg["proportions"],
                       true_segment_lengths_m=info["actor"]["true_segment_lengths_m"],
                       clothing_colours_linear_rgb=cfg.get("colours"), first_frame_hips=hips[0].tolist(),
                       first_frame_yaw_deg=math.degrees(yaw0), subject_placement=placement),
            other: dict(armature=other, gt_joints=f"gt_joints_{other}.npz", gt_masks=f"gt_masks_{other}",
                        source=partner["info"]["source"], proportions_from=cfg["partner"].get("proportions_from"),
                        proportions=cfg["partner"]["proportions"],
                        true_segment_lengths_m=subject.segment_lengths_of(partner["data"], rest, names),
                        clothing_colours_linear_rgb=cfg["partner"].get("colours"),
                        first_frame_hips=P2[0, rootb].tolist(), first_frame_yaw_deg=math.degrees(partner["yaw0"]),
                        subject_placement=partner["placement"])}
        info["partner"] = partner["info"]
        info["handshake"] = partner["handshake"]
        info["hidden"] = hidden
    (out / "scene_info.json").write_text(json.dumps(info, indent=1))
    log(f"[{name}] done -> {out}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=str(REPO.parent / "shared" / "data"),
                    help="folder with cmu/ and makehuman/ (default: ../shared/data next to the repository)")
    ap.add_argument("--scene", default="all", choices=[*SCENES, "all"])
    ap.add_argument("--out", default=str(HERE), help="where the scene folders go (default: sample_scenes/)")
    ap.add_argument("--samples", type=int, default=4, help="Cycles samples per pixel (denoised)")
    ap.add_argument("--quick", action="store_true", help="8 frames at quarter resolution: a smoke test")
    ap.add_argument("--no-render", action="store_true", help="skip the Cycles videos (motion, cameras, masks only)")
    args = ap.parse_args(argv)
    data = Path(args.data)
    if not (data / "cmu").is_dir() or not (data / "makehuman").is_dir():
        raise SystemExit(f"--data {data}: expected the folders cmu/ and makehuman/ there")
    names = list(SCENES) if args.scene == "all" else [args.scene]
    for n in names:
        build_scene(n, data, Path(args.out), args.samples, args.quick, not args.no_render)


if __name__ == "__main__":
    main()
