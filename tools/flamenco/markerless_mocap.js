// SPDX-License-Identifier: GPL-3.0-or-later
//
// Flamenco job type "Markerless Mocap": one take tracked in chunks on the farm's workers, then stitched (a take of
// several actors, whose armatures the job names, too: each actor's build fitted first, each chunk tracking them all).
//
// Each chunk is an `exec` task running `markerless_mocap track-chunk` (the command `batch` runs on a Dask
// worker), the chunks after the first after a `seed-chunks` task (where each starts); a last task runs
// `markerless_mocap stitch`, which waits for every chunk. The chunks are planned
// exactly as core/batch/plan.py plans them (tests/test_flamenco.py compares the two under Node), so a take
// sent here and one sent to `batch` share their chunk folders: a chunk finished by either is never redone.
// Install: tools/flamenco/README.md.

const JOB_TYPE = {
    label: "Markerless Mocap",
    description: "Track a take from calibrated multi-camera video in chunks, then stitch and smooth it",
    settings: [
        // The subject: the Flamenco add-on saves the .blend being submitted (the rigged character) and sets this.
        { key: "blendfile", type: "string", required: true, visible: false,
          description: "The subject .blend (the armature and its skinned mesh)" },
        { key: "capture", type: "string", subtype: "dir_path", required: true,
          description: "Capture folder (calibration + videos/) on the shared storage every worker reads" },
        { key: "take", type: "string", required: false,
          description: "Name of the take: letters, digits, - _ . (empty: the capture folder's name)" },
        { key: "frames", type: "string", required: true,
          eval: "f'{C.scene.mocap.frame_start}-{C.scene.mocap.frame_end}' if C.scene.mocap.use_frame_range " +
                "else f'0-{C.scene.mocap.capture_frames - 1}'",
          description: "Capture frames A-B to track, inclusive, counted from 0 (from the Mocap panel when submitted)" },
        { key: "output_root", type: "string", subtype: "dir_path", required: true,
          description: "Results go to <output_root>/<take>/, chunks to <output_root>/_chunks/ (as `batch --out`)" },
        { key: "chunk_frames", type: "int32", default: 300, propargs: { min: 1 },
          description: "Frames each chunk keeps: a few minutes of tracking per task" },
        { key: "warmup", type: "int32", default: 10, propargs: { min: 0 },
          description: "Frames a chunk tracks before its kept range, until it has settled (not kept)" },
        { key: "overlap", type: "int32", default: 5, propargs: { min: 0 },
          description: "Frames a chunk runs past its kept range, cross-faded with the next chunk" },
        { key: "smooth", type: "float", default: 8.0, propargs: { min: 0 },
          description: "Low-pass the stitched take at this many Hz (0: keep the poses as solved)" },
        { key: "armature", type: "string", required: false,
          description: "Armature to track if the subject has several (empty: its only one); several, separated by " +
                       "commas, track those actors at once, each one's build fitted on the take first" },
        { key: "actor", type: "string", subtype: "file_path", required: false,
          description: "Actor calibration (actor.json) to track with (empty: none)" },
        // Tracking options: the values and defaults of core/tracking/options.py (the test checks they agree).
        { key: "preset", type: "string", choices: ["full", "preview"], default: "full",
          description: "Speed against accuracy: full for the final take, preview for a quick look" },
        { key: "particles", type: "int32", default: 0, propargs: { min: 0 },
          description: "Pose hypotheses per iteration (0: the preset's)" },
        { key: "iterations", type: "int32", default: 0, propargs: { min: 0 },
          description: "Annealing iterations per frame (0: the preset's)" },
        { key: "seed", type: "int32", default: 0, propargs: { min: 0 },
          description: "Random seed: the same seed repeats the same result" },
        { key: "algorithm", type: "string", choices: ["isa", "apf", "pf", "fsa", "icp"], default: "isa",
          description: "Optimiser that searches each frame's pose" },
        { key: "likelihood", type: "string", default: "lsilh+edge+kp",
          choices: ["silh", "silh+edge", "silh+edgech", "silhch+color", "silhch", "lsilh+edge", "silh+edge+kp",
                    "lsilh+edge+kp", "lsilh+kp", "kp"],
          description: "Image cues the pose is scored against" },
        { key: "refine", type: "string", choices: ["icp", "none"], default: "icp",
          description: "Local fit of the silhouette outlines after the search" },
        { key: "background", type: "string", choices: ["auto", "plate", "median", "mog2", "knn"], default: "auto",
          description: "How the empty scene is known, for the background-subtraction silhouettes" },
        { key: "backend", type: "string", choices: ["auto", "numpy", "fast", "gpu"], default: "auto",
          description: "How poses are rendered on the worker (auto: its GPU if it has one, else compiled CPU)" },
        { key: "landmarks", type: "string", choices: ["auto", "full", "heavy"], default: "auto",
          description: "The learned model that finds the body's landmarks in each view (auto: the preset's; " +
                       "full: faster)" },
        // How a worker runs the add-on's command line: Blender with the extension installed, or a Python with the
        // package (the manager's variable {mocap_python}, one value per platform).
        { key: "runner", type: "string", choices: ["blender", "python"], default: "blender",
          description: "blender: {blender} --background --command markerless_mocap; python: {mocap_python} -m " +
                       "markerless_mocap" },
    ],
};

// The task type workers must list in their configuration (flamenco-worker.yaml, task_types).
const TASK_TYPE = "mocap";
const RUNNERS = {
    blender: { exe: "{blender}", args: ["--background", "--command", "markerless_mocap"] },
    python: { exe: "{mocap_python}", args: ["-m", "markerless_mocap"] },
};
// Tracking options passed to track-chunk and stitch alike: the chunk folders are named by a hash of them.
const TRACKING_OPTIONS = ["preset", "particles", "iterations", "seed", "algorithm", "likelihood", "refine",
                          "background", "backend", "landmarks"];
// `batch` keeps the chunk folders in OUT/_chunks, so a take may not be called that.
const CHUNKS_FOLDER = "_chunks";
// Frames an actor's build is fitted on, from the take's first (core/actor/frames.py DEFAULT_FRAMES); a shorter take
// of several actors is tracked with the rigs, as `track` and `batch` do.
const CALIBRATION_FRAMES = 20;

function compileJob(job) {
    const settings = job.settings;
    const take = takeName(settings);
    const [first, last] = parseFrames(settings.frames);
    const actors = armatureNames(settings);
    if (actors.length > 1 && settings.actor) {
        throw `actor "${settings.actor}": an actor calibration is one actor's, but the job tracks ` +
              `${actors.join(", ")}; leave it empty (each actor's build is fitted on the take)`;
    }
    const plan = planChunks(first, last, intSetting(settings, "chunk_frames"), intSetting(settings, "warmup"),
                            intSetting(settings, "overlap"));
    const chunksDir = path.join(settings.output_root, CHUNKS_FOLDER);
    const common = ["--scene", settings.blendfile, "--capture", settings.capture, "--take", take];
    for (const name of actors) common.push("--armature", name);
    if (settings.actor) common.push("--actor", settings.actor);
    const fits = actors.length > 1 && last - first + 1 >= CALIBRATION_FRAMES ?
        calibrationTasks(job, settings, take, first, actors, chunksDir) : [];
    for (const fit of fits) common.push("--actor", `${fit.actor}=${fit.file}`);
    common.push(...trackingArgs(settings));
    const who = actors.length > 1 ? `, ${actors.length} actors` : "";
    print(`Markerless Mocap: take ${take}, frames ${first}-${last}, ${plan.length} chunk(s)${who}`);

    const planArgs = ["--chunk-frames", String(intSetting(settings, "chunk_frames")),
                      "--warmup", String(intSetting(settings, "warmup")),
                      "--overlap", String(intSetting(settings, "overlap"))];
    // The chunks after the first start where the seed pass found the person (core/batch/seed.py), as `batch`
    // runs them; the stitch refuses a later chunk that started from the subject's placement instead.
    let seeds = null;
    if (plan.length > 1) {
        seeds = author.Task(`seeds-${take}`, TASK_TYPE);
        seeds.addCommand(mocapCommand(settings, ["seed-chunks", "--frames", `${first}-${last}`, "--chunks", chunksDir]
            .concat(planArgs, common)));
        for (const fit of fits) seeds.addDependency(fit.task);
        job.addTask(seeds);
    }
    const chunkTasks = plan.map((chunk) => {
        const task = author.Task(`track-${take}-${chunk.name}`, TASK_TYPE);
        task.addCommand(mocapCommand(settings, ["track-chunk", "--frames", `${chunk.track[0]}-${chunk.track[1]}`,
                                                "--chunks", chunksDir].concat(common)));
        if (chunk.index > 0) task.addDependency(seeds);
        else for (const fit of fits) task.addDependency(fit.task);
        job.addTask(task);
        return task;
    });
    const stitch = author.Task(`stitch-${take}`, TASK_TYPE);
    stitch.addCommand(mocapCommand(settings, [
        "stitch", "--frames", `${first}-${last}`, "--chunks", chunksDir, "--out", path.join(settings.output_root, take),
        ...planArgs, "--smooth", String(Number(settings.smooth)),
    ].concat(common)));
    for (const task of chunkTasks) {
        stitch.addDependency(task);
    }
    job.addTask(stitch);
}

// Several actors: each one's build fitted on the take's first frames by `calibrate`, into the folder `batch` fits
// it in (so the two share it), before anything is tracked. Returns {task, actor, file} per actor: every later
// command is given the file as --actor NAME=FILE.
function calibrationTasks(job, settings, take, first, actors, chunksDir) {
    return actors.map((name) => {
        const dir = path.join(chunksDir, take, "actors", actorFolderName(name));
        const task = author.Task(`calibrate-${take}-${actorFolderName(name)}`, TASK_TYPE);
        task.addCommand(mocapCommand(settings, [
            "calibrate", "--scene", settings.blendfile, "--capture", settings.capture, "--out", dir,
            "--frames", `${first}-${first + CALIBRATION_FRAMES - 1}`, "--armature", name,
        ].concat(trackingArgs(settings))));
        job.addTask(task);
        return {task, actor: name, file: path.join(dir, "actor.json")};
    });
}

// core/results/result_folder.py's actor_folder_name: an armature's name as a folder name.
function actorFolderName(name) {
    return name.replace(/[<>:"/\\|?*\x00-\x1f]/g, "_").replace(/^[ .]+|[ .]+$/g, "") || "armature";
}

function armatureNames(settings) {
    const names = String(settings.armature || "").split(",").map((name) => name.trim()).filter((name) => name);
    if (new Set(names).size !== names.length) throw `armature "${settings.armature}": a name given twice`;
    return names;
}

// The chunks of frames first..last (inclusive): core/batch/plan.py's plan_chunks, rule for rule. Throws a message
// naming the value for the inputs that function refuses.
function planChunks(first, last, chunkFrames, warmup, overlap) {
    const F0 = wholeNumber(first, "the first frame"), F1 = wholeNumber(last, "the last frame");
    const K = wholeNumber(chunkFrames, "chunk frames"), W = wholeNumber(warmup, "warm-up");
    const O = wholeNumber(overlap, "overlap");
    if (F0 < 0) throw `frames ${F0}-${F1}: capture frames count from 0`;
    if (F1 < F0) throw `frames ${F0}-${F1}: the last frame comes before the first`;
    if (K < 1) throw `chunk frames ${K}: a chunk keeps at least one frame`;
    if (W < 0 || O < 0) throw `warm-up ${W} / overlap ${O}: neither can be negative`;
    if (K < 2 * O) {
        throw `chunk frames ${K} with overlap ${O}: a chunk must keep at least twice the overlap ` +
              `(${2 * O} frames), so each cross-fade lies within one chunk`;
    }
    const N = F1 - F0 + 1;
    const n = Math.ceil(N / K);
    const start = (i) => F0 + Math.floor((i * N) / n); // integers: exact while i * N < 2^53
    const chunks = [];
    for (let i = 0; i < n; i++) {
        const keep = [start(i), start(i + 1) - 1];
        const track = [i === 0 ? F0 : Math.max(F0, keep[0] - W), i === n - 1 ? F1 : Math.min(F1, keep[1] + O)];
        chunks.push({ index: i, track: track, keep: keep, fade_in: i === 0 ? 0 : O,
                      name: `${pad6(track[0])}-${pad6(track[1])}` });
    }
    return chunks;
}

function mocapCommand(settings, args) {
    const runner = RUNNERS[settings.runner || "blender"];
    if (!runner) throw `runner ${settings.runner}: use one of ${Object.keys(RUNNERS).join(", ")}`;
    return author.Command("exec", { exe: runner.exe, args: runner.args.concat(args) });
}

function trackingArgs(settings) {
    const args = [];
    for (const key of TRACKING_OPTIONS) {
        const value = settings[key];
        if (value === undefined || value === null || value === "") continue;
        if ((key === "particles" || key === "iterations") && Number(value) === 0) continue; // the preset's
        args.push(`--${key}`, String(value));
    }
    return args;
}

function takeName(settings) {
    const take = settings.take || path.basename(String(settings.capture).replace(/[\\/]+$/, ""));
    // core/batch/chunk_folder.py's TAKE_NAME
    if (!/^[A-Za-z0-9][A-Za-z0-9._-]*$/.test(take) || take === CHUNKS_FOLDER) {
        throw `take name "${take}": use letters, digits, - _ . starting with a letter or a digit (it names the ` +
              `result folder)`;
    }
    return take;
}

// "A-B" (inclusive) or "A": capture frames counted from 0, as `track --frames`.
function parseFrames(text) {
    const match = /^\s*(\d+)\s*(?:-\s*(\d+)\s*)?$/.exec(String(text));
    if (!match) throw `frames "${text}": write the capture frames as A-B (inclusive, from 0), e.g. 0-599`;
    const first = Number(match[1]);
    return [first, match[2] === undefined ? first : Number(match[2])];
}

function intSetting(settings, key) {
    const value = settings[key];
    return wholeNumber(value === undefined || value === null || value === "" ? defaultOf(key) : value, key);
}

function defaultOf(key) {
    return JOB_TYPE.settings.find((s) => s.key === key).default;
}

function wholeNumber(value, what) {
    const number = typeof value === "string" && value.trim() !== "" ? Number(value) : value;
    if (typeof number !== "number" || !Number.isInteger(number)) throw `${what} must be a whole number, got ${value}`;
    return number;
}

function pad6(value) {
    let text = String(value);
    while (text.length < 6) text = "0" + text;
    return text;
}
