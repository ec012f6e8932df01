"""A long run in a worker thread that speaks to Blender's main thread only through a queue of plain messages.

Track and Calibrate Actor both run this way: the worker calls engine code (never bpy) and puts messages
(kind, *payload) on the queue; the operator's timer calls `drain` on the main thread, which hands each message
to the job's `on_<kind>` method, where properties are set and keys inserted. The worker always ends with a
"done" message, after an "error" one if it failed.
"""
import queue
import threading
import traceback


class WorkerJob:
    thread_name = "mocap-job"
    doing = "The run"  # what a bug's message says failed ("Tracking failed with an internal error ...")

    def __init__(self):
        self.queue = queue.Queue()
        self.thread = None
        self.done = False

    # ---- the worker's side
    def work(self):
        """The run itself, in the worker thread: put messages on self.queue (subclasses)."""
        raise NotImplementedError

    def describe_failure(self, exc):
        """(message, details) of an exception that ended `work`: what the user sees, then the traceback for the
        console. The user's error (a frame of footage, a full disk) is its message alone; anything else says it is
        a bug (operators/failures.py)."""
        from .failures import USER_ERRORS, bug_message

        if isinstance(exc, USER_ERRORS):
            return str(exc), ""
        return bug_message(exc, self.doing), traceback.format_exc()

    def start_worker(self):
        self.thread = threading.Thread(target=self._run_worker, name=self.thread_name, daemon=True)
        self.thread.start()

    def _run_worker(self):
        try:
            self.work()
        except Exception as exc:  # noqa: BLE001  (reported on the main thread, never swallowed)
            self.queue.put(("error", *self.describe_failure(exc)))
        finally:
            self.queue.put(("done",))

    # ---- the main thread's side
    def drain(self):
        """Hand every message that arrived to its on_<kind> method; return what those returned (None left out),
        in order. Sets `done` once the worker has ended."""
        results = []
        while True:
            try:
                kind, *payload = self.queue.get_nowait()
            except queue.Empty:
                return results
            if kind == "done":
                self.done = True
                continue
            result = getattr(self, f"on_{kind}")(*payload)
            if result is not None:
                results.append(result)

    def join(self):
        """Wait for the worker to end, then drain what it left."""
        if self.thread is not None:
            self.thread.join()
        return self.drain()
