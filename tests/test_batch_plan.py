"""The chunk plan (core/batch/plan.py): every frame kept once, each chunk's warm-up and overlap as the rule says
(the Flamenco job type reproduces it), bad sizes refused with their reason, and `plan-chunks --json`."""
import json

import pytest

from markerless_mocap.core.batch.plan import PlanError, plan_chunks, plan_to_json


def test_a_small_take_by_hand():
    """Frames 0-11 in chunks of at most 6, warm-up 3, overlap 2: the plan written out."""
    assert plan_to_json(0, 11, 6, 3, 2)["chunks"] == [
        {"index": 0, "track": [0, 7], "keep": [0, 5], "fade_in": 0, "name": "000000-000007"},
        {"index": 1, "track": [3, 11], "keep": [6, 11], "fade_in": 2, "name": "000003-000011"}]


@pytest.mark.parametrize("first,last,k,w,o", [(0, 0, 1, 0, 0), (0, 599, 300, 10, 5), (17, 618, 100, 20, 5),
                                              (5, 1000, 7, 30, 3), (0, 301, 300, 10, 5), (3, 9, 100, 10, 5)])
def test_every_frame_kept_once_with_warmup_and_overlap(first, last, k, w, o):
    chunks = plan_chunks(first, last, k, w, o)
    kept = [f for c in chunks for f in range(c.keep[0], c.keep[1] + 1)]
    assert kept == list(range(first, last + 1))
    n = len(chunks)
    assert n == -(-(last - first + 1) // k)
    lengths = [c.keep[1] - c.keep[0] + 1 for c in chunks]
    assert max(lengths) <= k and max(lengths) - min(lengths) <= 1  # as even as integers allow
    for i, c in enumerate(chunks):
        assert c.track[0] == (first if i == 0 else max(first, c.keep[0] - w))
        assert c.track[1] == (last if i == n - 1 else min(last, c.keep[1] + o))
        assert c.fade_in == (0 if i == 0 else o)
        if i:  # the cross-fade lies where both chunks tracked, inside this chunk's kept range
            assert chunks[i - 1].track[1] >= c.keep[0] + c.fade_in - 1
            assert c.fade_in <= lengths[i]


@pytest.mark.parametrize("args,words", [((5, 4, 10, 1, 1), "before the first"), ((-1, 4, 10, 1, 1), "from 0"),
                                        ((0, 9, 0, 1, 0), "at least one"), ((0, 9, 10, -1, 0), "negative"),
                                        ((0, 99, 9, 3, 5), "twice the overlap"), ((0, 9, 2.5, 1, 0), "whole")])
def test_bad_sizes_say_why(args, words):
    with pytest.raises(PlanError, match=words):
        plan_chunks(*args)


def test_plan_chunks_command_prints_the_plan(capsys):
    from markerless_mocap.operators.cli import main

    assert main(["plan-chunks", "--frames", "10-250", "--chunk-frames", "100", "--warmup", "8", "--overlap", "4",
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == plan_to_json(10, 250, 100, 8, 4)
    assert main(["plan-chunks", "--frames", "0-99", "--chunk-frames", "5", "--overlap", "3", "--json"]) == 2
    assert "twice the overlap" in capsys.readouterr().err


def test_the_seed_pass_visits_every_stride_and_each_chunk_start(tmp_path):
    import numpy as np

    from markerless_mocap.core.batch.seed import find_seed, seed_frames, seeds_path, write_seeds

    starts = [c.track[0] for c in plan_chunks(100, 400, 100, 10, 5)]
    assert starts == [100, 165, 240, 315]
    visit = seed_frames(100, starts, stride=5)
    assert visit[0] == 100 and visit[-1] == 315 and {165, 240, 315} <= set(visit)
    assert all(b - a <= 5 for a, b in zip(visit, visit[1:]))
    path = seeds_path(tmp_path, "take", 100, 400, "abc")
    poses = np.arange(len(visit) * 2, dtype=float).reshape(-1, 2)
    write_seeds(path, np.array(visit), poses, np.ones(len(visit), bool))
    assert np.array_equal(find_seed(tmp_path, "take", "abc", 165), poses[visit.index(165)])
    assert find_seed(tmp_path, "take", "abc", 166) is None and find_seed(tmp_path, "take", "other", 165) is None
    # several actors: a file each, and no actor's pose is read for another's (nor for the take of one)
    for sign, actor in ((-1.0, "Lead"), (2.0, "Partner")):
        write_seeds(seeds_path(tmp_path, "take", 100, 400, "abc", actor), np.array(visit), sign * poses,
                    np.ones(len(visit), bool))
    assert np.array_equal(find_seed(tmp_path, "take", "abc", 165, "Lead"), -poses[visit.index(165)])
    assert np.array_equal(find_seed(tmp_path, "take", "abc", 165, "Partner"), 2 * poses[visit.index(165)])
    assert np.array_equal(find_seed(tmp_path, "take", "abc", 165), poses[visit.index(165)])
    assert find_seed(tmp_path, "take", "abc", 165, "Nobody") is None
