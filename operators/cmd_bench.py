"""`bench`: speed of the likelihood engine (FK + LBS, reference NumPy path, fast numba path).

Scene: the sample subject (sample_scenes/walk/subject.blend or --subject). With the walk capture present
(calibration + videos + background plates) its cameras and first frame give the observed features;
otherwise 4 synthetic 640x480 cameras ring the subject and the "observation" is the body itself,
rendered by the reference path at a known pose (its silhouette, and its part boundaries as edges).
The poses evaluated scatter around that pose. The reference path is timed on a few poses and scaled up.
Then, per backend that runs here (numpy, fast, gpu: the GLSL path, when the GPU probe passes): energy
evaluations per second for batches of --poses (the paper's 200 particles; 15 iterations make 3000
evaluations per frame), and seconds per frame of the whole default pipeline (learned evidence, ISA 200 x 15,
the local fit; `lsilh+edge+kp`) tracked from the ground truth's pose on --pipeline-frames frames of the walk
capture; ratios against the NumPy reference.
Ends with one JSON line: reference_s, fast_s, ratio, fk_lbs_s, diffusion_vga_s, poses, views, resolution, backend,
..., and per backend `numpy`, `fast`, `gpu` ({evaluations_per_s, likelihood_s_per_frame, pipeline_s_per_frame,
*_vs_numpy}), `auto_backend`, `default_s_per_frame` (the default pipeline on the backend auto picks),
`preview_s_per_frame` (the preview preset's pipeline on that backend) and, with --two-actors, `two_actors`
(operators/bench_cast.py; null without).
"""
import json
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[1]
WALK = REPO_ROOT / "sample_scenes" / "walk"


def add_arguments(parser):
    parser.add_argument("--subject", type=Path, default=WALK / "subject.blend",
                        help="the .blend holding the rigged, skinned subject (default: the walk sample's)")
    parser.add_argument("--capture", type=Path, default=WALK,
                        help="capture folder whose first frame gives the observation (default: the walk sample; "
                             "synthetic cameras if it cannot be loaded)")
    parser.add_argument("--poses", type=int, default=200, help="poses per batch (default 200)")
    from ..core.tracking.options import OPTIONS

    parser.add_argument("--likelihood", default="silh+edge", choices=OPTIONS["likelihood"].values,
                        help="likelihood name (default silh+edge)")
    parser.add_argument("--scale", type=float, default=None,
                        help="energy resolution as a fraction of the capture's (default: the engine's)")
    parser.add_argument("--reference-poses", type=int, default=4,
                        help="poses the slow reference path is timed on, then scaled to --poses (default 4)")
    parser.add_argument("--repeats", type=int, default=7, help="timed repeats; the fastest counts (default 7)")
    # the CPU path timed against the reference; the GPU's figures come with the pipeline's when its probe passes
    parser.add_argument("--backend", default="auto", choices=[b for b in OPTIONS["backend"].values if b != "gpu"],
                        help="backend timed as the fast path (default auto)")
    parser.add_argument("--pipeline-frames", type=int, default=2,
                        help="frames of the default pipeline timed per backend after the start frame (default 2; "
                             "0 skips the pipeline timing)")
    parser.add_argument("--two-actors", type=Path, metavar="SCENE",
                        help="also time two actors tracked together against each alone on SCENE's first frames (a "
                             "folder with a subject.blend of two armatures and its capture, such as "
                             "sample_scenes/duet)")
    parser.add_argument("--landmarks", default=OPTIONS["landmarks"].default, choices=OPTIONS["landmarks"].values,
                        help=f"the landmark model of the --two-actors timing (default {OPTIONS['landmarks'].default}, "
                             "the Full preset's)")
    parser.add_argument("--iterations", type=int, default=15,
                        help="annealing iterations per frame for the per-frame figures (default 15: 200 x 15 = "
                             "the paper's 3000 evaluations)")


def _threads():
    try:
        import numba

        return numba.get_num_threads()
    except ImportError:
        return 1


def _best(fn, repeats):
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def ring_cameras(centre, n=4, radius=3.5, height=0.3, focal=550.0, size=(640, 480)):
    """n OpenCV cameras on a circle around `centre` (world Z up), all looking at it."""
    from ..core.capture.camera import Camera

    cams = []
    for i in range(n):
        a = np.deg2rad(20 + 360.0 * i / n)
        eye = np.asarray(centre, float) + [radius * np.cos(a), radius * np.sin(a), height]
        fwd = centre - eye
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        R = np.stack([right, np.cross(fwd, right), fwd])
        K = np.array([[focal, 0, (size[0] - 1) / 2], [0, focal, (size[1] - 1) / 2], [0, 0, 1]])
        cams.append(Camera(f"ring{i + 1}", K, np.zeros(0), R, -R @ eye, size[0], size[1]))
    return cams


def load_body(subject):
    import bpy

    from ..addon.scene_bridge import body_from_blender, find_armature
    from ..core.body.proxy import make_proxy

    if not Path(subject).is_file():
        raise FileNotFoundError(f"subject file {subject} does not exist: generate the sample scene "
                                "(bash setup.sh samples) or pass --subject PATH to a .blend with a rigged mesh")
    bpy.ops.wm.open_mainfile(filepath=str(subject))
    arm = find_armature(bpy.context.scene)
    body = body_from_blender(arm)
    return body, make_proxy(body, 2000)


def _capture_scene(folder, body, scale):
    """(cameras, first-frame features, pose near the subject) from a capture folder, or None."""
    try:
        from ..core.capture.capture import load_capture
        from ..core.evidence import BackgroundModel, compute_view_features

        capture = load_capture(folder)
        if not capture.backgrounds or len(capture.backgrounds) != len(capture.cameras):
            capture.close()
            return None
        images = capture.frames.read(0)
        feats = [compute_view_features(images[c.name], BackgroundModel.from_plate(capture.backgrounds[c.name]),
                                       scale=scale) for c in capture.cameras]
        cameras = capture.cameras
        capture.close()
        pose = body.default_pose()
        gt = Path(folder) / "gt_joints.npz"
        if gt.is_file():  # put the body where the subject's root joint is (else: the joints' centroid)
            with np.load(gt) as d:
                names, joints = [str(n) for n in d["names"]], d["positions"][0]
            root = body.skeleton.bone_names[body.root_bone]
            pose[body.translation_dofs] = joints[names.index(root)] if root in names else joints.mean(axis=0)
        return cameras, feats, pose
    except Exception as exc:  # noqa: BLE001  (any unusable capture: fall back to the synthetic scene)
        print(f"bench: capture {folder} not usable ({exc}); using synthetic cameras", file=sys.stderr)
        return None


def _learned_evidence_seconds(capture_dir, cameras, body, pose, repeats):
    """Seconds per frame of the learned evidence for every view: crops around the pose, one batched
    forward pass, landmarks and masks back in image pixels (the capture's frame 0, else grey images)."""
    from ..core.evidence.crops import crops_around
    from ..core.evidence.learned import LandmarkModel, locate

    images = None
    if capture_dir and Path(capture_dir).is_dir():
        try:
            from ..core.capture.capture import load_capture

            capture = load_capture(capture_dir)
            frame = capture.frames.read(0)
            images = [frame[c.name] for c in cameras]
            capture.close()
        except Exception:  # noqa: BLE001  (any unusable capture: time on synthetic images)
            images = None
    if images is None:
        images = [np.full((c.height, c.width, 3), 128, np.uint8) for c in cameras]
    model = LandmarkModel()
    boxes = crops_around(body, cameras, pose)
    model.evidence(images, boxes)  # warm up
    return _best(lambda: locate(model, images, boxes), repeats)


def _gpu_available():
    """Install the GLSL backend if the GPU probe (a subprocess) passes; (available, renderer or reason)."""
    from ..core.render import BackendUnavailableError
    from .backend_choice import choose_backend

    try:
        return True, choose_backend("gpu").renderer
    except BackendUnavailableError as exc:
        return False, str(exc)


def _pipeline_seconds(body, capture_dir, backend, n_frames, particles, iterations, preset="full"):
    """Seconds per frame of the default pipeline (TrackingSettings defaults: lsilh+edge+kp, ISA, the local
    fit; or another preset's, its own budget where particles/iterations are None) on `backend`, tracked from
    the ground truth's pose at frame 0, timed over frames 2..n_frames + 1."""
    from ..core.capture.capture import load_capture
    from ..core.tracking.settings import TrackingSettings
    from ..core.tracking.tracker import Tracker
    from .cmd_compare import true_first_pose
    from .track_session import build_motion_models

    capture = load_capture(capture_dir)
    try:
        prior, dynamics = build_motion_models(body, capture_dir, capture.frames.fps)
        settings = TrackingSettings.preset(preset, backend=backend, particles=particles, iterations=iterations)
        tracker = Tracker(body, capture, settings, prior=prior, dynamics=dynamics)
        tracker.initialise(0, initial_pose=true_first_pose(body, Path(capture_dir) / "gt_joints.npz", 0))
        seconds, evaluations = [], []
        tracker.track(1)  # not timed: the first frame after the start has nothing observed ahead for it
        for frame in range(2, n_frames + 2):
            t = time.perf_counter()
            est = tracker.track(frame, next_frame=frame + 1 if frame <= n_frames else None)
            seconds.append(time.perf_counter() - t)
            evaluations.append(est.evaluations)
        tracker.finish_prefetch()
        return float(np.mean(seconds)), float(np.mean(evaluations)), settings
    finally:
        capture.close()


def backend_table(body, proxy, cameras, feats, observed, poses, args):
    """Per backend: evaluations per second (poses x views per batch) and seconds per frame of the default
    pipeline. Returns {backend: figures} and the backend auto picks."""
    from ..core.energy import likelihood as lk
    from .backend_choice import choose_backend

    backends = ["numpy", "fast"]
    gpu_ok, gpu_note = _gpu_available()
    if gpu_ok:
        backends.append("gpu")
        print(f"GLSL path: Blender's gpu module on {gpu_note}")
    else:
        print(f"GLSL path not timed: {gpu_note}")
    auto = choose_backend("auto")
    print(f"backend auto picks here: {auto.used} ({auto.reason})")
    n_per_frame = args.poses * args.iterations
    table = {}
    for backend in backends:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=".*anatomical prior.*")
            model = lk.EnergyModel(body, proxy, cameras, args.likelihood, scale=fast_scale(args), backend=backend)
        model.set_reference_pose(lk.default_pose_at(body, observed))
        model.set_frame(feats)
        batch = poses if backend != "numpy" else poses[:min(args.reference_poses, len(poses))]
        model(batch)  # warm up (JIT, shaders)
        wall = _best(lambda model=model, batch=batch: model(batch),
                     max(1, min(3, args.repeats)) if backend == "numpy" else args.repeats)
        cpu0 = time.process_time()
        model(batch)
        cpu = time.process_time() - cpu0
        per_s = len(batch) / wall
        row = {"evaluations_per_s": round(per_s, 1), "likelihood_s_per_frame": round(n_per_frame / per_s, 3),
               "likelihood_cpu_s_per_batch": round(cpu * len(poses) / len(batch), 4)}
        if args.pipeline_frames > 0 and args.capture and (Path(args.capture) / "gt_joints.npz").is_file():
            sec, evals, settings = _pipeline_seconds(body, args.capture, backend, args.pipeline_frames, args.poses,
                                                     args.iterations)
            row["pipeline_s_per_frame"] = round(sec, 3)
            row["pipeline_evaluations_per_frame"] = evals
        table[backend] = row
    base = table["numpy"]
    for row in table.values():
        row["evaluations_vs_numpy"] = round(row["evaluations_per_s"] / base["evaluations_per_s"], 2)
        if "pipeline_s_per_frame" in row:
            row["pipeline_vs_numpy"] = round(base["pipeline_s_per_frame"] / row["pipeline_s_per_frame"], 2)
    views = len(cameras)
    print(f"per backend, {args.likelihood}, {views} views, batches of {args.poses} poses; "
          f"{n_per_frame} evaluations per frame ({args.poses} x {args.iterations}); default pipeline "
          f"(lsilh+edge+kp, ISA {args.poses} x {args.iterations} + local fit) over {args.pipeline_frames} frames:")
    for backend, row in table.items():
        pipe = (f"; default pipeline {row['pipeline_s_per_frame']:.2f} s/frame "
                f"({row['pipeline_vs_numpy']:.1f}x numpy)") if "pipeline_s_per_frame" in row else ""
        print(f"  {backend:5s}: {row['evaluations_per_s']:8.0f} evaluations/s ({row['evaluations_vs_numpy']:.1f}x "
              f"numpy) = {row['likelihood_s_per_frame']:.2f} s of likelihood per frame{pipe}")
    return table, auto.used


def fast_scale(args):
    from ..core.energy import likelihood as lk

    return lk.ENERGY_SCALE if args.scale is None else args.scale


def synthetic_features(model, pose):
    from ..core.evidence.view_features import ViewFeatures, distance_to_mask
    from ..core.evidence.view_features import EDGE_DT_CAP_PX

    feats = []
    for v in range(len(model.cameras)):
        labels, sil, boundary = model.render(pose, v)
        ab = np.stack([labels * 9.0 - 60.0, 40.0 - labels * 7.0], axis=-1).astype(np.float32)  # a colour per part
        feats.append(ViewFeatures(sil, distance_to_mask(sil), boundary,
                                  np.minimum(distance_to_mask(boundary), EDGE_DT_CAP_PX * model.scale), ab,
                                  model.scale))
    return feats


def run(args):
    from ..core.energy import likelihood as lk
    from ..core import render
    from ..core.evidence import edge_enhancing_diffusion

    if args.poses < 1 or args.reference_poses < 1 or args.repeats < 1:
        print("bench: --poses, --reference-poses and --repeats must be at least 1", file=sys.stderr)
        return 2
    try:
        body, proxy = load_body(args.subject)
    except (FileNotFoundError, ValueError) as exc:
        print(f"bench: {exc}", file=sys.stderr)
        return 1
    scale = lk.ENERGY_SCALE if args.scale is None else args.scale
    rng = np.random.default_rng(0)
    scene = _capture_scene(args.capture, body, scale) if args.capture and Path(args.capture).is_dir() else None
    lo = np.where(np.isfinite(body.lower), body.lower, -0.3)
    hi = np.where(np.isfinite(body.upper), body.upper, 0.3)
    if scene is None:
        centre = body.default_pose()
        cameras = ring_cameras(centre[body.translation_dofs])
        observed = centre.copy()
        joints = np.setdiff1d(np.arange(body.n_dof), np.r_[body.translation_dofs, body.root_rotation_dofs])
        observed[joints] = np.clip(rng.normal(0, 0.2, len(joints)), lo[joints], hi[joints])
        source = "synthetic ring of 4 cameras, observation = body rendered at a known pose"
    else:
        cameras, feats, observed = scene
        source = f"capture {args.capture} frame 0"
    with warnings.catch_warnings():  # the image terms are timed; the prior (cheap) is not part of it
        warnings.filterwarnings("ignore", message=".*anatomical prior.*")
        fast_model = lk.EnergyModel(body, proxy, cameras, args.likelihood, scale=scale, backend=args.backend)
        ref_model = lk.EnergyModel(body, proxy, cameras, args.likelihood, scale=scale, backend="numpy")
    if scene is None:
        feats = synthetic_features(ref_model, observed)
    for m in (fast_model, ref_model):
        m.set_reference_pose(lk.default_pose_at(body, observed))
        m.set_frame(feats)
        if m.weights.color:
            m.init_color_model(observed)
    poses = np.tile(observed, (args.poses, 1))
    poses += rng.normal(0, 1, poses.shape) * body.scale
    poses = np.clip(poses, body.lower, body.upper)

    w, h = fast_model.cameras[0].width, fast_model.cameras[0].height
    print(f"subject: {args.subject} ({len(proxy.faces)} proxy triangles, {body.n_dof} DOF)")
    print(f"scene: {source}; {len(cameras)} views at {cameras[0].width}x{cameras[0].height}, "
          f"energy resolution {w}x{h} (scale {scale:g}), likelihood {args.likelihood}, "
          f"back-face culling {'on' if fast_model.cull else 'off'}")
    fk = _best(lambda: proxy.deform(body, poses), args.repeats)
    print(f"FK + LBS, {args.poses} poses: {fk * 1e3:.1f} ms")
    t = time.perf_counter()
    fast_model(poses)  # JIT compile (or load the cache) and warm up
    print(f"first fast call (JIT or cache load): {time.perf_counter() - t:.2f} s")
    fast = _best(lambda: fast_model(poses), args.repeats)
    cpu0 = time.process_time()
    fast_model(poses)
    fast_cpu = time.process_time() - cpu0
    backend = fast_model.backend
    print(f"{backend} path, {args.poses} poses x {len(cameras)} views (incl. FK, LBS, projection): {fast * 1e3:.1f} ms "
          f"wall (best of {args.repeats}), {fast_cpu * 1e3:.0f} ms CPU over all threads")
    n_ref = min(args.reference_poses, args.poses)
    ref_few = _best(lambda: ref_model(poses[:n_ref]), max(1, min(3, args.repeats)))
    ref = ref_few * args.poses / n_ref
    print(f"reference path: {ref_few * 1e3:.1f} ms for {n_ref} poses -> {ref:.2f} s for {args.poses} "
          f"(extrapolated linearly)")
    agree = np.allclose(fast_model(poses[:n_ref]), ref_model(poses[:n_ref]), rtol=0.01)
    print(f"ratio reference / fast: {ref / fast:.1f}x; energies agree within 1%: {agree}")
    ab = np.random.default_rng(4).normal(0, 20, (480, 640, 2)).astype(np.float32)
    diffusion = _best(lambda: edge_enhancing_diffusion(ab, steps=5), args.repeats)
    print(f"colour features: edge-enhancing diffusion (AOS, 5 steps) of a 640x480 a/b image: {diffusion * 1e3:.0f} ms")
    learned = _learned_evidence_seconds(args.capture, cameras, body, observed, args.repeats)
    print(f"learned evidence (BlazePose crops, landmarks and person masks), {len(cameras)} views: "
          f"{learned * 1e3:.0f} ms per frame")
    table, auto_backend = backend_table(body, proxy, cameras, feats, observed, poses, args)
    default = table.get(auto_backend, {}).get("pipeline_s_per_frame")
    if default is not None:
        print(f"default pipeline at the paper's budget on the backend auto picks ({auto_backend}): "
              f"{default:.2f} s per frame")
    preview = None
    if default is not None:
        preview, evals, settings = _pipeline_seconds(body, args.capture, auto_backend, args.pipeline_frames, None,
                                                     None, preset="preview")
        print(f"preview preset ({settings.particles} x {settings.iterations}, the local fit at the search's "
              f"resolution) on {auto_backend}: {preview:.2f} s per frame")
    two_actors = None
    if args.two_actors is not None:
        from .bench_cast import cast_seconds

        two_actors = cast_seconds(args.two_actors, landmarks=args.landmarks)
        names = ", ".join(two_actors["armatures"]) + f"; landmarks: {two_actors['landmarks']}"
        print(f"two actors ({names}) tracked together: {two_actors['two_s_per_frame']:.2f} s per frame against "
              f"one alone {two_actors['one_s_per_frame']:.2f}, the mean of the two ({two_actors['ratio']:.2f}x)")
    print(json.dumps({**table, "auto_backend": auto_backend, "default_s_per_frame": default, "two_actors": two_actors,
                      "preview_s_per_frame": None if preview is None else round(preview, 3),
                      "load_average": [round(x, 2) for x in os.getloadavg()],
                      "learned_evidence_s": round(learned, 4), "reference_s": round(ref, 4), "fast_s": round(fast, 4),
                      "ratio": round(ref / fast, 2), "fk_lbs_s": round(fk, 4), "diffusion_vga_s": round(diffusion, 4),
                      "fast_cpu_s": round(fast_cpu, 4), "poses": args.poses, "views": len(cameras),
                      "resolution": f"{w}x{h}", "backend": backend, "likelihood": args.likelihood,
                      "reference_poses_timed": n_ref, "energies_agree": bool(agree), "threads": _threads(),
                      "render_backends": list(render.BACKENDS)}))
    return 0
