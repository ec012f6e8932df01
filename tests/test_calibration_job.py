"""The Calibrate button's worker (operators/actor_calibration.CalibrationJob), without Blender: progress per
frame, Esc stops after the frame being solved and saves nothing, a failure comes back as a message."""
import threading
from types import SimpleNamespace

from markerless_mocap.operators.actor_calibration import CalibrationJob


class FakeSession:
    """solve_next hands out frames one at a time, each when the test releases it; the capture records close."""

    def __init__(self, n, landmarks=None):
        self.frames = list(range(n))
        self.release = threading.Semaphore(0)
        self._cancel = threading.Event()
        self.writer = SimpleNamespace(estimates=[])
        self.capture = SimpleNamespace(closed=False)
        self.capture.close = lambda: setattr(self.capture, "closed", True)
        self.landmarks = landmarks

    @property
    def cancelled(self):
        return self._cancel.is_set()

    def cancel(self):
        self._cancel.set()
        self.release.release()  # a frame being solved finishes

    def solve_next(self):
        if not self.frames or self.cancelled:
            return None
        self.release.acquire()
        est = SimpleNamespace(frame=self.frames.pop(0), landmarks=self.landmarks, landmark_visibility=None)
        self.writer.estimates.append(est)
        return est


def _wait_for(job, solved):
    for _ in range(500):
        job.drain()
        if job.solved >= solved or job.done:
            return
        threading.Event().wait(0.01)


def test_cancel_stops_after_the_current_frame_and_saves_nothing():
    session = FakeSession(10)
    job = CalibrationJob(session, 10)
    job.start()
    for _ in range(3):
        session.release.release()
    _wait_for(job, 3)
    assert job.solved == 3 and job.fraction == 0.3 and "frame 3 of 10" in job.status and not job.done
    job.request_cancel()
    job.join()
    assert job.done and job.fit is None and job.error is None
    assert job.solved <= 4 and session.capture.closed


def test_a_run_without_landmarks_fails_with_a_message_naming_the_fix():
    session = FakeSession(2)
    job = CalibrationJob(session, 2)
    job.start()
    session.release.release()
    session.release.release()
    job.join()
    assert job.done and job.fit is None and job.solved == 2 and session.capture.closed
    assert "calibration needs the learned landmarks" in job.error[0] and "lsilh+edge+kp" in job.error[0]
