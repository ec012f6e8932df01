// Tests of the Flamenco job type (markerless_mocap.js) under Node, with a stand-in for Flamenco's `author`.
//
//   node --test tools/flamenco/plan.test.js
//
// Alone it checks the plan's own rules and the tasks' dependencies. tests/test_flamenco.py runs it with
// MOCAP_FLAMENCO_CASES=<json>: the Python planner's plans (core/batch/plan.py) to equal, the Python option values
// and defaults to agree with, and jobs to compile into MOCAP_FLAMENCO_DUMP for the Python side to check their
// command lines against the real command-line parser.
"use strict";
const { test } = require("node:test");
const assert = require("node:assert/strict");
const fs = require("node:fs");
const nodePath = require("node:path");
const vm = require("node:vm");

const JOB_FILE = nodePath.join(__dirname, "markerless_mocap.js");
const CASES = process.env.MOCAP_FLAMENCO_CASES
    ? JSON.parse(fs.readFileSync(process.env.MOCAP_FLAMENCO_CASES, "utf8")) : null;

// What Flamenco's job compiler gives a job type: print, a path module (POSIX paths), author.Task / author.Command.
function standInAuthor() {
    return {
        Task(name, type) {
            return {
                name, type, commands: [], dependencies: [],
                addCommand(command) { this.commands.push(command); },
                addDependency(task) { this.dependencies.push(task); },
            };
        },
        Command(name, parameters) { return { name, parameters }; },
    };
}

function loadJobType() {
    const printed = [];
    const context = vm.createContext({
        print: (...parts) => printed.push(parts.join(" ")),
        path: { join: nodePath.posix.join, basename: nodePath.posix.basename, dirname: nodePath.posix.dirname },
        author: standInAuthor(),
    });
    vm.runInContext(fs.readFileSync(JOB_FILE, "utf8"), context, { filename: JOB_FILE });
    // top-level const/function declarations live in the context's global scope
    const get = (name) => vm.runInContext(name, context);
    return { JOB_TYPE: get("JOB_TYPE"), compileJob: get("compileJob"), planChunks: get("planChunks"), printed };
}

// Objects made inside the vm have that realm's prototypes: compare their plain JSON form.
const plain = (value) => JSON.parse(JSON.stringify(value));

function compile(settings, name = "job") {
    const jobType = loadJobType();
    const defaults = {};
    for (const s of jobType.JOB_TYPE.settings) {
        if (s.default !== undefined) defaults[s.key] = s.default;
    }
    const job = { name, created: new Date(0), settings: Object.assign(defaults, settings), tasks: [],
                  addTask(task) { this.tasks.push(task); } };
    jobType.compileJob(job);
    return job;
}

function thrownBy(fn) {
    try {
        fn();
    } catch (err) {
        return String(err);
    }
    return null;
}

const SAMPLE = { blendfile: "/farm/subjects/anna.blend", capture: "/farm/captures/walk01",
                 output_root: "/farm/results", frames: "0-999" };

test("the kept ranges split the take evenly, each chunk tracks its warm-up and overlap", () => {
    const { planChunks } = loadJobType();
    for (const [F0, F1] of [[0, 0], [0, 9], [3, 599], [0, 36000 - 1], [17, 1000]]) {
        for (const K of [1, 10, 60, 300, 2000]) {
            for (const [W, O] of [[0, 0], [10, 5], [25, 0]]) {
                if (K < 2 * O) continue;
                const plan = plain(planChunks(F0, F1, K, W, O));
                const N = F1 - F0 + 1;
                assert.equal(plan.length, Math.ceil(N / K));
                let next = F0;
                const sizes = plan.map((c) => c.keep[1] - c.keep[0] + 1);
                for (const [i, c] of plan.entries()) {
                    assert.equal(c.index, i);
                    assert.equal(c.keep[0], next, "kept ranges are contiguous");
                    next = c.keep[1] + 1;
                    assert.ok(c.track[0] <= c.keep[0] && c.keep[1] <= c.track[1]);
                    assert.equal(c.track[0], i === 0 ? F0 : Math.max(F0, c.keep[0] - W));
                    assert.equal(c.track[1], i === plan.length - 1 ? F1 : Math.min(F1, c.keep[1] + O));
                    assert.equal(c.fade_in, i === 0 ? 0 : O);
                    assert.match(c.name, /^\d{6}-\d{6}$/);
                    assert.deepEqual(c.name.split("-").map(Number), c.track);
                }
                assert.equal(next, F1 + 1, "the last kept frame is the take's last");
                assert.ok(Math.max(...sizes) <= K && Math.max(...sizes) - Math.min(...sizes) <= 1, `${sizes}`);
            }
        }
    }
});

test("bad plan inputs are refused with the value named", () => {
    const { planChunks } = loadJobType();
    assert.match(thrownBy(() => planChunks(-1, 10, 300, 10, 5)), /count from 0/);
    assert.match(thrownBy(() => planChunks(20, 10, 300, 10, 5)), /20-10.*before the first/);
    assert.match(thrownBy(() => planChunks(0, 10, 0, 10, 5)), /chunk frames 0/);
    assert.match(thrownBy(() => planChunks(0, 10, 8, 10, 5)), /chunk frames 8 with overlap 5/);
    assert.match(thrownBy(() => planChunks(0, 10, 2.5, 10, 5)), /whole number/);
});

test("one exec task per chunk, and a stitch task that depends on every one of them", () => {
    const job = compile(SAMPLE);
    const { planChunks } = loadJobType();
    const plan = planChunks(0, 999, 300, 10, 5);
    assert.equal(job.tasks.length, plan.length + 2);
    const seeds = job.tasks[0];
    assert.equal(seeds.name, "seeds-walk01");
    assert.equal(plain(seeds.commands[0].parameters.args)[3], "seed-chunks");
    const chunkTasks = job.tasks.slice(1, -1);
    const stitch = job.tasks[job.tasks.length - 1];
    for (const [i, task] of chunkTasks.entries()) {
        assert.equal(task.name, `track-walk01-${plan[i].name}`);
        assert.equal(task.type, "mocap");
        // the first chunk starts at the placement, as `track` does; the others where the seed pass found the person
        assert.deepEqual(task.dependencies.map((d) => d.name), i === 0 ? [] : ["seeds-walk01"]);
        assert.equal(task.commands.length, 1);
        const { name, parameters } = task.commands[0];
        assert.equal(name, "exec");
        assert.equal(parameters.exe, "{blender}");
        const args = plain(parameters.args);
        assert.deepEqual(args.slice(0, 4), ["--background", "--command", "markerless_mocap", "track-chunk"]);
        assert.equal(args[args.indexOf("--frames") + 1], `${plan[i].track[0]}-${plan[i].track[1]}`);
        assert.equal(args[args.indexOf("--chunks") + 1], "/farm/results/_chunks");
    }
    assert.equal(stitch.name, "stitch-walk01");
    assert.equal(stitch.dependencies.length, chunkTasks.length);
    for (const task of chunkTasks) {
        assert.ok(stitch.dependencies.includes(task), `stitch does not wait for ${task.name}`);
    }
    const args = plain(stitch.commands[0].parameters.args);
    assert.equal(args[3], "stitch");
    assert.equal(args[args.indexOf("--out") + 1], "/farm/results/walk01");
});

test("several actors: each build fitted first, then chunks tracking them all, no saved calibration", () => {
    const job = compile(Object.assign({}, SAMPLE, { armature: " Lead,Partner " }));
    const { planChunks } = loadJobType();
    const plan = planChunks(0, 999, 300, 10, 5);
    const names = job.tasks.map((t) => t.name);
    assert.deepEqual(names.slice(0, 3), ["calibrate-walk01-Lead", "calibrate-walk01-Partner", "seeds-walk01"]);
    assert.equal(job.tasks.length, 2 + 1 + plan.length + 1);
    const fits = job.tasks.slice(0, 2);
    for (const [i, name] of ["Lead", "Partner"].entries()) {
        const args = plain(fits[i].commands[0].parameters.args);
        assert.equal(args[3], "calibrate");
        assert.equal(args[args.indexOf("--armature") + 1], name);
        assert.equal(args[args.indexOf("--out") + 1], `/farm/results/_chunks/walk01/actors/${name}`);
        assert.equal(args[args.indexOf("--frames") + 1], "0-19");
    }
    for (const task of job.tasks.slice(2)) {
        const args = plain(task.commands[0].parameters.args);
        assert.deepEqual(args.filter((_, i) => args[i - 1] === "--armature"), ["Lead", "Partner"], task.name);
        assert.deepEqual(args.filter((_, i) => args[i - 1] === "--actor"),
                         ["Lead=/farm/results/_chunks/walk01/actors/Lead/actor.json",
                          "Partner=/farm/results/_chunks/walk01/actors/Partner/actor.json"], task.name);
    }
    // nothing is tracked before both builds are fitted
    assert.deepEqual(job.tasks[2].dependencies, fits);
    assert.deepEqual(job.tasks[3].dependencies, fits);
    const short = compile(Object.assign({}, SAMPLE, { armature: "Lead,Partner", frames: "0-9" }));
    assert.deepEqual(short.tasks.map((t) => t.name), ["track-walk01-000000-000009", "stitch-walk01"]);
    assert.match(thrownBy(() => compile(Object.assign({}, SAMPLE, { armature: "Lead,Partner", actor: "/a.json" }))),
                 /an actor calibration is one actor's/);
    assert.match(thrownBy(() => compile(Object.assign({}, SAMPLE, { armature: "Lead, Lead" }))), /a name given twice/);
});

test("the python runner, a named take and bad settings", () => {
    const job = compile(Object.assign({}, SAMPLE, { runner: "python", take: "day2.take-07", frames: "5" }));
    assert.equal(job.tasks.length, 2); // one chunk: no seed pass
    assert.equal(job.tasks[0].commands[0].parameters.exe, "{mocap_python}");
    assert.deepEqual(plain(job.tasks[0].commands[0].parameters.args).slice(0, 3), ["-m", "markerless_mocap",
                                                                                  "track-chunk"]);
    assert.equal(job.tasks[0].name, "track-day2.take-07-000005-000005");
    assert.match(thrownBy(() => compile(Object.assign({}, SAMPLE, { frames: "1-2, 5-9" }))), /frames "1-2, 5-9"/);
    assert.match(thrownBy(() => compile(Object.assign({}, SAMPLE, { take: "my take" }))), /take name "my take"/);
    assert.match(thrownBy(() => compile(Object.assign({}, SAMPLE, { take: "_chunks" }))), /take name "_chunks"/);
    assert.match(thrownBy(() => compile(Object.assign({}, SAMPLE, { take: ".hidden" }))), /take name ".hidden"/);
    assert.match(thrownBy(() => compile(Object.assign({}, SAMPLE, { chunk_frames: 4 }))), /chunk frames 4/);
});

if (CASES) {
    test("the plans equal the Python planner's", () => {
        const { planChunks } = loadJobType();
        assert.ok(CASES.plans.length > 0);
        for (const { args, plan, error } of CASES.plans) {
            if (error !== null) {
                const thrown = thrownBy(() => planChunks(...args));
                assert.notEqual(thrown, null, `${args}: Python refused (${error}), the job type did not`);
                continue;
            }
            assert.deepEqual(plain(planChunks(...args)), plan.chunks, `plan of ${args}`);
        }
    });

    test("settings offer the Python options' values and defaults", () => {
        const { JOB_TYPE } = loadJobType();
        const byKey = Object.fromEntries(JOB_TYPE.settings.map((s) => [s.key, s]));
        for (const [key, { values, default: value }] of Object.entries(CASES.options)) {
            assert.ok(byKey[key], `no setting ${key}`);
            if (values.length) {
                assert.deepEqual(plain(byKey[key].choices), values, key);
                assert.equal(byKey[key].default, value, key);
            } else if (key === "particles" || key === "iterations") {
                assert.equal(byKey[key].default, 0, `${key}: 0 stands for the preset's`);
            } else {
                assert.equal(byKey[key].default, value, key);
            }
        }
        for (const [key, value] of Object.entries(CASES.defaults)) {
            assert.equal(byKey[key].default, value, key);
        }
    });

    test("take names are refused where the Python side refuses them", () => {
        for (const { name, ok } of CASES.take_names) {
            const thrown = thrownBy(() => compile(Object.assign({}, SAMPLE, { take: name })));
            assert.equal(thrown === null, ok, `take ${JSON.stringify(name)}: ${thrown}`);
        }
    });

    test("jobs compile (written for the Python side)", () => {
        const compiled = CASES.jobs.map((settings) => compile(settings).tasks.map((task) => ({
            name: task.name, type: task.type, commands: plain(task.commands),
            depends_on: task.dependencies.map((d) => d.name),
        })));
        fs.writeFileSync(process.env.MOCAP_FLAMENCO_DUMP, JSON.stringify(compiled));
    });
}
