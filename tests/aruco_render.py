"""Frames with ArUco markers at known poses, made with OpenCV itself: the marker image (with a white
margin of half its side) is warped onto a grey background where the camera model projects its
corners, then blurred and given sensor noise."""

from __future__ import annotations

import cv2
import numpy as np

K_720P = np.array([[1000.0, 0, 639.5], [0, 1000.0, 359.5], [0, 0, 1]])
NO_DISTORTION = np.zeros(5)


def frontal(z: float, x: float = 0.0, y: float = 0.0):
    """A marker facing the camera: marker x = camera x, marker y up (camera y down), z towards the camera."""
    return cv2.Rodrigues(np.diag([1.0, -1.0, -1.0]))[0].reshape(3), np.array([x, y, z], dtype=float)


def tilted(z: float, x: float, y: float, tilt_deg: float, yaw_deg: float):
    base = np.diag([1.0, -1.0, -1.0])
    tilt = cv2.Rodrigues(np.array([np.radians(tilt_deg), 0, 0]))[0]
    yaw = cv2.Rodrigues(np.array([0, 0, np.radians(yaw_deg)]))[0]
    return cv2.Rodrigues(base @ tilt @ yaw)[0].reshape(3), np.array([x, y, z], dtype=float)


def render(markers, k=K_720P, size=(1280, 720), dictionary=cv2.aruco.DICT_4X4_50, length=0.15, blur=0.8,
           noise=2.0, seed=0, background=110):
    """``markers``: [(id, rvec, tvec)] with the marker's pose in the camera frame."""
    rng = np.random.default_rng(seed)
    width, height = size
    frame = np.full((height, width), float(background))
    aruco = cv2.aruco.getPredefinedDictionary(dictionary)
    for marker_id, rvec, tvec in markers:
        side = 240
        image = cv2.aruco.generateImageMarker(aruco, marker_id, side, borderBits=1)
        margin = side // 2
        image = cv2.copyMakeBorder(image, margin, margin, margin, margin, cv2.BORDER_CONSTANT, value=255)
        half = length / 2 * (image.shape[0] / side)
        corners3d = np.array([[-half, half, 0], [half, half, 0], [half, -half, 0], [-half, -half, 0]])
        projected, _ = cv2.projectPoints(corners3d, np.asarray(rvec, float), np.asarray(tvec, float), k, NO_DISTORTION)
        n = image.shape[0]
        source = np.float32([[-0.5, -0.5], [n - 0.5, -0.5], [n - 0.5, n - 0.5], [-0.5, n - 0.5]])
        homography = cv2.getPerspectiveTransform(source, projected.reshape(4, 2).astype(np.float32))
        warped = cv2.warpPerspective(image.astype(np.float32), homography, size, flags=cv2.INTER_LINEAR)
        mask = cv2.warpPerspective(np.ones_like(image, dtype=np.float32), homography, size, flags=cv2.INTER_LINEAR)
        frame = frame * (1 - mask) + warped
    if blur:
        frame = cv2.GaussianBlur(frame, (0, 0), blur)
    if noise:
        frame = frame + rng.normal(0, noise, frame.shape)
    return np.clip(frame, 0, 255).astype(np.uint8)


def write_calibration(path, k=K_720P, size=(1280, 720), dist=NO_DISTORTION):
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    storage.write("image_width", size[0])
    storage.write("image_height", size[1])
    storage.write("camera_matrix", k)
    storage.write("distortion_coefficients", dist.reshape(1, -1))
    storage.release()
