"""What the chunks' reports say frame by frame, carried into the stitched take's report.json.

Each chunk's report.json records per frame which views the tracker left out or took the landmarks from, how many
landmarks it set aside, which limbs it searched again, which estimates it turned round and which solutions the
root gate refused. The stitched take keeps, for every frame, what the chunk that gave it that frame recorded
(core/batch/plan.py, `keep`), so a take tracked in chunks reports the same things as a take tracked in one piece,
and `stitch` and `batch` can print the same end-of-take lines as `track`.
"""
from __future__ import annotations

# report.json keys holding {frame (str): value}
FRAME_MAPS = ("views_shared", "landmarks_set_aside", "unlike_clothes", "views_left_out", "turned_round")
# report.json keys holding [{"frame": int, ...}]
FRAME_LISTS = ("limb_recoveries", "root_gate")


def _kept(chunk, frame):
    return chunk.keep[0] <= int(frame) <= chunk.keep[1]


def per_frame_facts(chunks, reports):
    """{key: merged} of FRAME_MAPS and FRAME_LISTS over the chunks (core/batch/plan.Chunk) and their report.json
    dicts (same order): each frame's entry from the chunk that keeps it; keys no chunk recorded are absent."""
    merged = {}
    for key in FRAME_MAPS:
        frames = {}
        for chunk, report in zip(chunks, reports):
            frames.update({str(f): v for f, v in (report.get(key) or {}).items() if _kept(chunk, f)})
        if frames:
            merged[key] = dict(sorted(frames.items(), key=lambda item: int(item[0])))
    for key in FRAME_LISTS:
        entries = [e for chunk, report in zip(chunks, reports) for e in (report.get(key) or [])
                   if _kept(chunk, e["frame"])]
        if entries:
            merged[key] = sorted(entries, key=lambda e: e["frame"])
    return merged
