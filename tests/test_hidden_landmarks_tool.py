"""tools/hidden_landmarks.py's test of a point the body hides, on a square of two triangles in front of a camera:
a point behind it by more than the margin is hidden, one just behind it or beside it is not, nor one the camera
cannot see."""
import numpy as np
from tool_helpers import load_tool

from markerless_mocap.core.capture.camera import Camera, rodrigues_to_matrix


def test_a_point_behind_the_surface_by_more_than_the_margin_is_hidden():
    tool = load_tool("hidden_landmarks")
    K = np.array([[200.0, 0, 80], [0, 200.0, 60], [0, 0, 1]])
    camera = Camera("c", K, [], rodrigues_to_matrix([0, 0, 0]), [0, 0, 0], 160, 120)  # looks down +z
    square = np.array([[-0.3, -0.3, 2.0], [0.3, -0.3, 2.0], [0.3, 0.3, 2.0], [-0.3, 0.3, 2.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    points = np.array([[0.0, 0.0, 2.5],     # behind the square's middle by 0.5 m: hidden
                       [0.0, 0.0, 2.05],    # behind it by 0.05 m, within the margin: the surface's own flesh
                       [0.0, 0.0, 1.5],     # in front of it
                       [0.5, 0.0, 2.5],     # beside it (projects off the square)
                       [0.0, 0.0, -1.0]])   # behind the camera
    hidden = tool.hidden_in_view(square, faces, camera, points, margin=0.1)
    assert hidden.tolist() == [True, False, False, False, False]
    assert tool.hidden_in_view(square, faces, camera, points, margin=0.01)[:2].tolist() == [True, True]
