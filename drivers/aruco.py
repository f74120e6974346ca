"""Vehicle poses from ArUco markers seen by a camera (OpenCV 4.8+ / 5.0 API).

Two set-ups, both described in the scene's ``cameras:`` section:

- **fixed**: a camera with a known place in the tank watches markers on the vehicles; each marker's
  pose (solvePnP with IPPE_SQUARE) goes through the camera's pose into the scene frame, then through
  the marker's offset on the hull to the vehicle's reference point;
- **onboard**: a vehicle's own camera sees markers whose places in the tank are known (a map); one
  solvePnP over the corners of every visible map marker gives the camera's pose in the tank, and the
  camera's mount gives the vehicle's.

A single square marker has two plausible poses (the planar flip ambiguity).  Both IPPE solutions are
kept; when their reprojection errors are close, the one whose rotation is nearest the marker's last
accepted pose wins.

Frames: the scene frame is NED (x north, y east, z down).  A placement ``{position, rpy_deg}`` is the
position of a frame's origin and its roll, pitch, yaw (degrees, applied yaw then pitch then roll) in
its parent.  OpenCV's camera frame is x right, y down, z forward; a marker's frame has its centre at
the origin, x right, y up and z out of the marker towards the camera.

Capture and detection run in a thread (:class:`CameraThread`) that hands poses to the daemon's loop;
the loop never waits for a frame.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import cv2
import numpy as np

from .reader_thread import ReaderThread

log = logging.getLogger(__name__)

DICTIONARIES = tuple(name for name in dir(cv2.aruco) if name.startswith("DICT_") and not name.endswith("_MAX"))
AMBIGUITY_RATIO = 1.5  # second IPPE solution this much worse (reprojection) or more: no ambiguity


class CameraError(RuntimeError):
    """A camera that cannot be used (missing device, broken calibration…), said plainly."""


# -- geometry -------------------------------------------------------------------------------------


def rotation_rpy(rpy_deg: tuple[float, float, float]) -> np.ndarray:
    """R = Rz(yaw) · Ry(pitch) · Rx(roll), from degrees."""
    roll, pitch, yaw = (math.radians(a) for a in rpy_deg)
    cr, sr, cp, sp, cy, sy = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def transform(rotation: np.ndarray, translation) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = rotation
    t[:3, 3] = np.asarray(translation, dtype=float).reshape(3)
    return t


def placement(position, rpy_deg) -> np.ndarray:
    return transform(rotation_rpy(rpy_deg), position)


def invert(t: np.ndarray) -> np.ndarray:
    r = t[:3, :3]
    return transform(r.T, -r.T @ t[:3, 3])


def yaw_pitch_roll(r: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) in radians of a rotation matrix (ZYX)."""
    pitch = -math.asin(max(-1.0, min(1.0, r[2, 0])))
    roll = math.atan2(r[2, 1], r[2, 2])
    yaw = math.atan2(r[1, 0], r[0, 0])
    return roll, pitch, yaw


def marker_object_points(length: float) -> np.ndarray:
    h = length / 2
    return np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]], dtype=np.float64)


# -- calibration ----------------------------------------------------------------------------------


@dataclass
class Calibration:
    matrix: np.ndarray
    distortion: np.ndarray
    size: tuple[int, int] | None = None


def load_calibration(path: str) -> Calibration:
    """OpenCV's calibration YAML (camera_matrix, distortion_coefficients) or a ROS camera_info YAML."""
    import os

    if not os.path.exists(path):
        raise CameraError(f"calibration file {path} does not exist")
    try:
        storage = cv2.FileStorage(path, cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:  # OpenCV's parser raises through a SystemError on bad YAML
        reason = str(exc.__cause__ or exc).strip().splitlines()[-1]
        raise CameraError(f"calibration file {path} is not valid OpenCV YAML: {reason}") from None
    try:
        if not storage.isOpened():
            raise CameraError(f"calibration file {path} is not an OpenCV YAML/XML file")
        matrix = _read_matrix(storage.getNode("camera_matrix"), (3, 3))
        distortion = _read_matrix(storage.getNode("distortion_coefficients"), None)
        if matrix is None:
            raise CameraError(f"calibration file {path} has no camera_matrix")
        if matrix.shape != (3, 3) or not np.all(np.isfinite(matrix)) or matrix[0, 0] <= 0 or matrix[1, 1] <= 0:
            raise CameraError(f"calibration file {path}: camera_matrix must be 3x3 with positive focal lengths")
        if distortion is None:
            distortion = np.zeros(5)
        width, height = storage.getNode("image_width").real(), storage.getNode("image_height").real()
        size = (int(width), int(height)) if width and height else None
        return Calibration(matrix.astype(np.float64), distortion.reshape(-1).astype(np.float64), size)
    except cv2.error as exc:
        raise CameraError(f"calibration file {path} cannot be read: {exc}") from None
    finally:
        storage.release()


def _read_matrix(node, shape) -> np.ndarray | None:
    if node is None or node.empty():
        return None
    if node.isMap() and not node.getNode("data").empty():  # ROS camera_info: rows, cols, data
        data = node.getNode("data")
        values = [data.at(i).real() for i in range(data.size())]
        rows = int(node.getNode("rows").real() or 1)
        return np.array(values, dtype=np.float64).reshape(rows, -1) if shape is None else \
            np.array(values, dtype=np.float64).reshape(shape)
    matrix = node.mat()
    return None if matrix is None else np.asarray(matrix, dtype=np.float64)


# -- detection and pose ---------------------------------------------------------------------------


def make_detector(dictionary: str) -> Any:
    if dictionary not in DICTIONARIES:
        raise CameraError(f"unknown ArUco dictionary {dictionary!r}")
    parameters = cv2.aruco.DetectorParameters()
    parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    # by name: the dictionary the scene names, by its name
    return cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)), parameters)


@dataclass
class MarkerPose:
    marker: int
    camera_marker: np.ndarray  # 4x4, marker frame in the camera frame
    error_px: float


@dataclass
class Estimator:
    """Marker poses in the camera frame, with the flip ambiguity resolved against the last pose."""

    calibration: Calibration
    marker_length: float
    dictionary: str = "DICT_4X4_50"
    last: dict[int, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.detector = make_detector(self.dictionary)
        self.object_points = marker_object_points(self.marker_length)

    def detect(self, image: np.ndarray) -> tuple[list[np.ndarray], list[int]]:
        gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        corners, ids, _ = self.detector.detectMarkers(gray)
        if ids is None:
            return [], []
        return [c.reshape(4, 2).astype(np.float64) for c in corners], [int(i) for i in ids.reshape(-1)]

    def marker_pose(self, marker: int, corners: np.ndarray) -> MarkerPose | None:
        k, d = self.calibration.matrix, self.calibration.distortion
        count, rvecs, tvecs, errors = cv2.solvePnPGeneric(self.object_points, corners, k, d,
                                                          flags=cv2.SOLVEPNP_IPPE_SQUARE)
        if not count:
            return None
        candidates = [(float(errors[i][0]) if errors is not None else 0.0,
                       transform(cv2.Rodrigues(rvecs[i])[0], tvecs[i])) for i in range(count)]
        candidates.sort(key=lambda c: c[0])
        best_error, best = candidates[0]
        if len(candidates) > 1 and marker in self.last:
            other_error, other = candidates[1]
            if other_error < AMBIGUITY_RATIO * max(best_error, 1e-6):
                previous = self.last[marker][:3, :3]
                if _angle(other[:3, :3], previous) < _angle(best[:3, :3], previous):
                    best_error, best = other_error, other
        self.last[marker] = best
        return MarkerPose(marker, best, best_error)


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    cosine = (np.trace(a.T @ b) - 1) / 2
    return math.acos(max(-1.0, min(1.0, cosine)))


@dataclass(frozen=True)
class Sighting:
    vehicle: str
    position: tuple[float, float, float]
    attitude: tuple[float, float, float]


class FixedCameraTracker:
    """A camera at a known place watching markers on vehicles."""

    def __init__(self, estimator: Estimator, camera_position, camera_rpy_deg,
                 markers: dict[int, tuple[str, tuple[float, float, float]]]):
        self.estimator = estimator
        self.scene_camera = placement(camera_position, camera_rpy_deg)
        self.markers = markers  # id -> (vehicle, offset of the vehicle's reference point in the marker frame)

    def process(self, image: np.ndarray) -> list[Sighting]:
        sightings = []
        corners, ids = self.estimator.detect(image)
        for marker, c in zip(ids, corners):
            if marker not in self.markers:
                continue
            pose = self.estimator.marker_pose(marker, c)
            if pose is None:
                continue
            vehicle, offset = self.markers[marker]
            scene_marker = self.scene_camera @ pose.camera_marker
            position = scene_marker @ np.array([*offset, 1.0])
            sightings.append(Sighting(vehicle, tuple(float(v) for v in position[:3]),
                                      yaw_pitch_roll(scene_marker[:3, :3])))
        return sightings


class OnboardTracker:
    """A vehicle's own camera localising itself on markers fixed in the tank."""

    def __init__(self, estimator: Estimator, vehicle: str, mount_position, mount_rpy_deg,
                 marker_map: dict[int, tuple[tuple[float, float, float], tuple[float, float, float]]]):
        self.estimator = estimator
        self.vehicle = vehicle
        self.vehicle_camera = placement(mount_position, mount_rpy_deg)
        self.corners_in_scene = {
            marker: (placement(position, rpy) @ np.hstack([estimator.object_points, np.ones((4, 1))]).T).T[:, :3]
            for marker, (position, rpy) in marker_map.items()
        }

    def process(self, image: np.ndarray) -> list[Sighting]:
        corners, ids = self.estimator.detect(image)
        object_points, image_points = [], []
        for marker, c in zip(ids, corners):
            if marker in self.corners_in_scene:
                object_points.append(self.corners_in_scene[marker])
                image_points.append(c)
        if not object_points:
            return []
        calibration = self.estimator.calibration
        objects = np.vstack(object_points)
        images = np.vstack(image_points)
        flags = cv2.SOLVEPNP_IPPE if len(object_points) == 1 else cv2.SOLVEPNP_SQPNP
        ok, rvec, tvec = cv2.solvePnP(objects, images, calibration.matrix, calibration.distortion, flags=flags)
        if not ok:
            return []
        rvec, tvec = cv2.solvePnPRefineLM(objects, images, calibration.matrix, calibration.distortion, rvec, tvec)
        camera_scene = transform(cv2.Rodrigues(rvec)[0], tvec)
        scene_vehicle = invert(camera_scene) @ invert(self.vehicle_camera)
        return [Sighting(self.vehicle, tuple(float(v) for v in scene_vehicle[:3, 3]),
                         yaw_pitch_roll(scene_vehicle[:3, :3]))]


def open_capture(source: int | str) -> Any:
    capture = cv2.VideoCapture(source)
    if not capture.isOpened():
        capture.release()
        raise CameraError(f"cannot open camera {source!r} (no such device, file or stream)")
    return capture


class CameraThread(ReaderThread):
    """Reads frames and tracks markers in its own thread; hands each frame's sightings to ``deliver``
    (which must be thread-safe, e.g. the scheduler's ``post``).  A camera that fails is reopened every
    two seconds; a video file that ends is read again from the start."""

    def __init__(self, name: str, source: int | str, tracker: Any, deliver: Callable[[list[Sighting]], Any],
                 fps_limit: float | None = None):
        self.name = name
        self.source = source
        self.tracker = tracker
        self.deliver = deliver
        self.fps_limit = fps_limit
        self.fps = 0.0
        self.frames = 0
        self.error: str | None = None
        super().__init__(f"camera-{name}")

    def _run(self) -> None:
        window_start, window_frames = time.monotonic(), 0
        capture = None
        while not self._stop.is_set():
            if capture is None:
                try:
                    capture = open_capture(self.source)
                    self.error = None
                except CameraError as exc:
                    if self.error != str(exc):
                        log.warning("camera %s: %s; retrying", self.name, exc)
                    self.error = str(exc)
                    self._stop.wait(2.0)
                    continue
            started = time.monotonic()
            ok, frame = capture.read()
            if not ok:
                if isinstance(self.source, str) and capture.get(cv2.CAP_PROP_FRAME_COUNT) > 0:
                    capture.set(cv2.CAP_PROP_POS_FRAMES, 0)  # a video file: loop it
                    continue
                capture.release()
                capture = None
                continue
            try:
                sightings = self.tracker.process(frame)
            except cv2.error as exc:
                log.warning("camera %s: %s", self.name, exc)
                sightings = []
            self.frames += 1
            window_frames += 1
            now = time.monotonic()
            if now - window_start >= 1.0:
                self.fps = window_frames / (now - window_start)
                window_start, window_frames = now, 0
            if sightings:
                self.deliver(sightings)
            if self.fps_limit:
                self._stop.wait(max(0.0, 1.0 / self.fps_limit - (time.monotonic() - started)))
        if capture is not None:
            capture.release()
