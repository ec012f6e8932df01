"""The worker-thread pattern Track and Calibrate share (operators/worker_job.py): messages reach their on_<kind>
handlers on the draining thread, in order; a failure comes back as an error message; "done" always ends it."""
from markerless_mocap.operators.worker_job import WorkerJob


class Counting(WorkerJob):
    def __init__(self, fail_after=None):
        super().__init__()
        self.fail_after = fail_after
        self.seen, self.errors = [], []

    def work(self):
        for i in range(5):
            if i == self.fail_after:
                raise RuntimeError("disk full")
            self.queue.put(("item", i))

    def on_item(self, i):
        self.seen.append(i)
        return i * 10 if i % 2 == 0 else None  # drain() returns what the handlers return, None left out

    def on_error(self, message, details):
        self.errors.append((message, details))


def test_messages_reach_their_handlers_in_order_and_done_ends_the_run():
    job = Counting()
    job.start_worker()
    returned = job.join()
    assert job.seen == [0, 1, 2, 3, 4] and returned == [0, 20, 40]
    assert job.done and not job.errors and not job.thread.is_alive()


def test_a_failure_comes_back_as_an_error_message_after_what_was_done():
    job = Counting(fail_after=3)
    job.start_worker()
    job.join()
    assert job.seen == [0, 1, 2] and job.done
    (message, details), = job.errors
    # not an InputError: reported as a bug of ours, with what it was, and the traceback kept
    assert "(RuntimeError: disk full)" in message and "This is a bug in Markerless Mocap" in message
    assert "Traceback" in details
