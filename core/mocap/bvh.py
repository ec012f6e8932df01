"""BVH reader (Biovision hierarchy): skeleton + per-frame channels -> MotionClip.

Rotation channels are applied in the order listed: `Zrotation Yrotation Xrotation` gives
R = Rz @ Ry @ Rx (the convention of the CMU conversions and of Blender's importer).
Position channels on non-root joints are ignored (rare; the rest OFFSET is used).
"""
from pathlib import Path

import numpy as np

from .clip import MotionClip, MotionFileError, euler_matrix, guess_units_to_metres

_ROT = {"Xrotation": "X", "Yrotation": "Y", "Zrotation": "Z"}
_POS = {"Xposition": 0, "Yposition": 1, "Zposition": 2}


def read_bvh(path, units_to_metres=None):
    """Read a BVH file. `units_to_metres`: the file's linear unit in metres; None guesses it from
    the skeleton's size (m, cm, mm, inch or CMU units); give it explicitly when you know it."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"BVH file not found: {path}")
    tokens = path.read_text(errors="replace").split()
    pos = 0

    def fail(msg):
        raise MotionFileError(f"{path}: {msg}. Is it a valid BVH file (HIERARCHY ... MOTION)?")

    def take():
        nonlocal pos
        if pos >= len(tokens):
            fail("unexpected end of file")
        pos += 1
        return tokens[pos - 1]

    def expect(word):
        tok = take()
        if tok != word:
            fail(f"expected '{word}' but found '{tok}'")

    names, parents, offsets, channels, end_sites = [], [], [], [], {}
    expect("HIERARCHY")
    stack = []   # indices of open joints; -2 marks an End Site block
    tok = take()
    if tok != "ROOT":
        fail(f"expected 'ROOT' after HIERARCHY, found '{tok}'")
    pending = ("joint", take())
    while True:
        kind, name = pending
        expect("{")
        expect("OFFSET")
        try:
            off = [float(take()) for _ in range(3)]
        except ValueError:
            fail(f"bad OFFSET numbers in '{name}'")
        if kind == "end":
            end_sites[stack[-1]] = np.array(off)
            stack.append(-2)
        else:
            idx = len(names)
            names.append(name)
            parents.append(stack[-1] if stack else -1)
            offsets.append(off)
            expect("CHANNELS")
            try:
                n = int(take())
            except ValueError:
                fail(f"bad CHANNELS count in '{name}'")
            ch = [take() for _ in range(n)]
            bad = [c for c in ch if c not in _ROT and c not in _POS]
            if bad:
                fail(f"unknown channel(s) {bad} in joint '{name}'")
            channels.append(ch)
            stack.append(idx)
        # children or closing braces
        while True:
            tok = take()
            if tok == "JOINT":
                pending = ("joint", take())
                break
            if tok == "End":
                expect("Site")
                if stack[-1] < 0:
                    fail("End Site inside an End Site")
                pending = ("end", None)
                break
            if tok == "}":
                stack.pop()
                if not stack:
                    pending = None
                    break
                continue
            fail(f"unexpected token '{tok}' in the hierarchy")
        if pending is None:
            break

    expect("MOTION")
    expect("Frames:")
    try:
        n_frames = int(take())
    except ValueError:
        fail("bad 'Frames:' count")
    expect("Frame")
    expect("Time:")
    frame_time = float(take())
    if frame_time <= 0:
        fail(f"Frame Time must be positive, got {frame_time}")
    n_ch = sum(len(c) for c in channels)
    values = tokens[pos:pos + n_frames * n_ch]
    if len(values) < n_frames * n_ch:
        fail(f"MOTION holds {len(values)} numbers, expected {n_frames} frames x {n_ch} channels")
    data = np.asarray(values, dtype=np.float64).reshape(n_frames, n_ch)

    J = len(names)
    local = np.empty((n_frames, J, 3, 3))
    root_pos = np.zeros((n_frames, 3))
    col = 0
    for j, ch in enumerate(channels):
        rot_axes = "".join(_ROT[c] for c in ch if c in _ROT)
        rot_cols = [col + k for k, c in enumerate(ch) if c in _ROT]
        if rot_axes:
            local[:, j] = euler_matrix(rot_axes, data[:, rot_cols])
        else:
            local[:, j] = np.eye(3)
        if parents[j] < 0:
            for k, c in enumerate(ch):
                if c in _POS:
                    root_pos[:, _POS[c]] = data[:, col + k]
        col += len(ch)
    # the root OFFSET is added by FK; with position channels it is usually zero
    fps = 1.0 / frame_time
    if abs(fps - round(fps)) < 1e-4 * fps:
        fps = float(round(fps))   # "Frame Time: .0083333" means 120 fps, not 120.0005
    clip = MotionClip(names, np.array(parents), np.array(offsets), np.tile(np.eye(3), (J, 1, 1)),
                      local, root_pos, fps, 1.0, end_sites)
    clip.units_to_metres = float(units_to_metres) if units_to_metres else guess_units_to_metres(clip)
    return clip
