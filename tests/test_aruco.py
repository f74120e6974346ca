"""ArUco tracking with OpenCV on frames rendered at known poses (nothing of OpenCV mocked)."""

import math
import time

import cv2
import numpy as np
import pytest

from aruco_render import frontal, render, tilted, write_calibration
from hilgate.drivers.aruco import (
    CameraError, CameraThread, Estimator, FixedCameraTracker, OnboardTracker, load_calibration, open_capture,
    placement,
)


@pytest.fixture
def calibration(tmp_path):
    path = tmp_path / "camera.yaml"
    write_calibration(path)
    return load_calibration(str(path))


def test_fixed_camera_finds_the_vehicle_within_a_centimetre_at_1_to_2_m(calibration):
    estimator = Estimator(calibration, 0.15, "DICT_4X4_50")
    tracker = FixedCameraTracker(estimator, (0, 0, 0), (0, 0, 0), {7: ("rov", (0.0, 0.0, 0.0))})
    rng = np.random.default_rng(3)
    errors = []
    for i in range(40):
        z = rng.uniform(1.0, 2.0)
        x, y = rng.uniform(-0.3, 0.3), rng.uniform(-0.2, 0.2)
        rvec, tvec = tilted(z, x, y, rng.uniform(-30, 30), rng.uniform(-180, 180))
        [sighting] = tracker.process(render([(7, rvec, tvec)], seed=i))
        errors.append(math.dist(sighting.position, tvec))
    assert max(errors) < 0.01, sorted(errors)[-3:]


def test_camera_placement_and_marker_offset_carry_into_the_scene_frame(calibration):
    # a camera 2 m above the tank origin looking straight down (x north stays image right... see below)
    estimator = Estimator(calibration, 0.15)
    camera_position, camera_rpy = (1.0, 2.0, -2.0), (0.0, 0.0, 0.0)  # camera z (forward) = scene z (down)
    tracker = FixedCameraTracker(estimator, camera_position, camera_rpy, {7: ("rov", (0.0, 0.0, -0.1))})
    rvec, tvec = frontal(1.5, 0.2, -0.1)
    [sighting] = tracker.process(render([(7, rvec, tvec)]))
    # marker frame z points back at the camera (scene -z): an offset of -0.1 along it is 0.1 m deeper
    expected = np.array(camera_position) + tvec + np.array([0, 0, 0.1])
    assert np.allclose(sighting.position, expected, atol=0.01)


def test_flip_ambiguity_resolved_by_the_last_pose(calibration):
    estimator = Estimator(calibration, 0.15)
    rvec, tvec = tilted(1.5, 0.0, 0.0, 20, 30)
    truth = cv2.Rodrigues(rvec)[0]
    poses = []
    for i in range(10):
        corners, ids = estimator.detect(render([(7, rvec, tvec)], seed=i))
        poses.append(estimator.marker_pose(7, corners[0]).camera_marker[:3, :3])
    angles = [math.degrees(math.acos(max(-1, min(1, (np.trace(p.T @ truth) - 1) / 2)))) for p in poses]
    assert max(angles) < 5  # never the flipped solution, which is tens of degrees away


def test_onboard_camera_localises_on_a_marker_map(calibration):
    # two markers on the tank floor; the camera looks down at them from a known place
    camera = placement((0.5, 0.3, -1.6), (0, 0, 0))  # camera axes = scene axes (z down)
    marker_map = {3: ((0.3, 0.2, 0.0), (180.0, 0.0, 0.0)), 4: ((0.7, 0.4, 0.0), (180.0, 0.0, 0.0))}
    frames = []
    for marker, (position, rpy) in marker_map.items():
        camera_marker = np.linalg.inv(camera) @ placement(position, rpy)
        frames.append((marker, cv2.Rodrigues(camera_marker[:3, :3])[0].reshape(3), camera_marker[:3, 3]))
    tracker = OnboardTracker(Estimator(calibration, 0.15), "rov", (0, 0, 0), (0, 0, 0), marker_map)
    [sighting] = tracker.process(render(frames))
    assert math.dist(sighting.position, (0.5, 0.3, -1.6)) < 0.01


def test_a_video_file_read_back_through_the_camera_thread(tmp_path, calibration):
    path = str(tmp_path / "tank.avi")
    writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 30, (1280, 720), isColor=False)
    truths = []
    for i in range(20):
        rvec, tvec = frontal(1.2 + 0.02 * i, 0.1, 0.05)
        truths.append(tvec)
        writer.write(render([(7, rvec, tvec)], seed=i))
    writer.release()
    tracker = FixedCameraTracker(Estimator(calibration, 0.15), (0, 0, 0), (0, 0, 0), {7: ("rov", (0, 0, 0))})
    seen = []
    thread = CameraThread("tank", path, tracker, seen.extend)
    thread.start()
    deadline = time.monotonic() + 20
    while len(seen) < 20 and time.monotonic() < deadline:
        time.sleep(0.05)
    thread.stop()
    assert len(seen) >= 20 and thread.error is None
    for sighting, truth in zip(seen[:20], truths):
        assert math.dist(sighting.position, truth) < 0.015  # after JPEG compression


def test_missing_camera_and_broken_calibration_are_clear_errors(tmp_path):
    with pytest.raises(CameraError, match="cannot open camera"):
        open_capture(str(tmp_path / "nope.avi"))
    with pytest.raises(CameraError, match="does not exist"):
        load_calibration(str(tmp_path / "nope.yaml"))
    broken = tmp_path / "broken.yaml"
    broken.write_text("%YAML:1.0\n---\nimage_width: 640\n")
    with pytest.raises(CameraError, match="no camera_matrix"):
        load_calibration(str(broken))
    garbage = tmp_path / "garbage.yaml"
    garbage.write_text("this is : : not [ yaml\n")
    with pytest.raises(CameraError):
        load_calibration(str(garbage))


def test_ros_camera_info_calibration(tmp_path):
    path = tmp_path / "ros.yaml"
    path.write_text("image_width: 640\nimage_height: 480\ncamera_name: raspicam\n"
                    "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [834.0, 0.0, 320.0, 0.0, 834.0, 240.0, 0.0, 0.0, 1.0]\n"
                    "distortion_model: plumb_bob\n"
                    "distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [0.46, 0.0, 0.0, 0.0, 0.0]\n")
    calibration = load_calibration(str(path))
    assert calibration.matrix[0, 0] == 834.0 and calibration.distortion[0] == 0.46 and calibration.size == (640, 480)
