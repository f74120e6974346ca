#!/usr/bin/env python3
"""ArUco tracking speed and accuracy at 1280x720, against bare OpenCV on the same frames.

Frames are rendered at known poses (tests/aruco_render.py: the marker warped onto a background,
blurred, with sensor noise) before timing.  Timed on one core (cv2.setNumThreads(1)):

- hilgate: FixedCameraTracker.process(frame) -> vehicle positions in the scene frame (detection,
  IPPE_SQUARE with both solutions and the flip check, the transforms);
- bare: ArucoDetector.detectMarkers + solvePnP(IPPE_SQUARE) per marker, nothing else.

Printed: frames per second for one and four markers, hilgate's overhead over bare OpenCV (target
>= 30 frames/s, overhead <= 15 %), and the position error distribution at 1-2 m.

    python benchmarks/aruco.py [--frames 200]
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

import cv2
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
from aruco_render import K_720P, render, tilted  # noqa: E402

from hilgate.drivers.aruco import Calibration, Estimator, FixedCameraTracker, marker_object_points  # noqa: E402

LENGTH = 0.15


def scenes(count: int, markers: int, seed: int = 1):
    rng = np.random.default_rng(seed)
    frames, truths = [], []
    # far enough apart that no marker's white margin covers another at 1 m
    offsets = [(-0.35, -0.3), (0.35, -0.3), (-0.35, 0.3), (0.35, 0.3)][:markers] if markers > 1 else [(0.0, 0.0)]
    for i in range(count):
        placed = []
        for marker, (ox, oy) in enumerate(offsets):
            z = rng.uniform(1.0, 2.0)
            rvec, tvec = tilted(z, ox * z / 1.5 + rng.uniform(-0.05, 0.05), oy * z / 1.5 + rng.uniform(-0.05, 0.05),
                                rng.uniform(-30, 30), rng.uniform(-180, 180))
            placed.append((marker, rvec, tvec))
        frames.append(render(placed, seed=i))
        truths.append({marker: tvec for marker, _, tvec in placed})
    return frames, truths


def time_it(function, frames, repeat: int = 2) -> float:
    best = math.inf
    for _ in range(repeat):
        start = time.perf_counter()
        for frame in frames:
            function(frame)
        best = min(best, time.perf_counter() - start)
    return len(frames) / best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=200)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    calibration = Calibration(K_720P, np.zeros(5), (1280, 720))
    object_points = marker_object_points(LENGTH)
    for markers in (1, 4):
        frames, truths = scenes(args.frames, markers)
        estimator = Estimator(calibration, LENGTH)
        tracker = FixedCameraTracker(estimator, (0, 0, 0), (0, 0, 0), {m: (f"v{m}", (0, 0, 0)) for m in range(4)})
        detector = estimator.detector

        def bare(frame):
            corners, ids, _ = detector.detectMarkers(frame)
            for c in corners if ids is not None else ():
                cv2.solvePnP(object_points, c.reshape(4, 2), K_720P, None, flags=cv2.SOLVEPNP_IPPE_SQUARE)

        fps_bare = time_it(bare, frames)
        fps_hilgate = time_it(tracker.process, frames)
        errors = []
        for frame, truth in zip(frames, truths):
            for sighting in tracker.process(frame):
                errors.append(1000 * math.dist(sighting.position, truth[int(sighting.vehicle[1:])]))
        errors.sort()
        found = len(errors) / (len(frames) * markers)
        print(f"{markers} marker{'s' if markers > 1 else ' '}: hilgate {fps_hilgate:6.1f} frames/s, bare OpenCV "
              f"{fps_bare:6.1f} frames/s, overhead {100 * (fps_bare / fps_hilgate - 1):5.1f} %   "
              f"(target >= 30 frames/s, <= 15 %)")
        print(f"           error at 1-2 m: median {errors[len(errors) // 2]:.1f} mm, p95 "
              f"{errors[int(0.95 * (len(errors) - 1))]:.1f} mm, max {errors[-1]:.1f} mm; {100 * found:.0f} % found")


if __name__ == "__main__":
    main()
