"""tools/contact_sheet.py: every N-th tracked frame x every camera, from the overlay videos."""
import cv2
import numpy as np

from markerless_mocap.tools.contact_sheet import contact_sheet, result_frames


def test_sheet_rows_are_every_nth_frame_and_columns_the_cameras(tmp_path):
    res = tmp_path / "res"
    (res / "overlay").mkdir(parents=True)
    frames = np.arange(5, 30)                       # a run over capture frames 5..29
    np.savez(res / "joints.npz", names=np.array(["Hips"]), frames=frames, positions=np.zeros((len(frames), 1, 3)))
    for k, name in enumerate(("cam1", "cam2")):
        vw = cv2.VideoWriter(str(res / "overlay" / f"{name}.mp4"), cv2.VideoWriter_fourcc(*"mp4v"), 30, (64, 48))
        for i in range(len(frames)):
            vw.write(np.full((48, 64, 3), 8 * i + 40 * k, np.uint8))
        vw.release()
    assert result_frames(res) == frames.tolist()
    sheet = contact_sheet(res, every=10, tile_height=96)
    assert sheet.shape == (3 * 96, 2 * 128, 3)      # tracked frames 0, 10, 20 -> capture frames 5, 15, 25
    # row 1 of cam2 is overlay frame 10 (grey 8*10+40 = 120), below the 22-pixel label band
    assert abs(float(sheet[96 + 60, 128 + 64].mean()) - 120) < 12
