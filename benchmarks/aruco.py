#!/usr/bin/env python3
"""ArUco tracking speed and accuracy at 1280x720, against bare OpenCV on the same frames.

Frames are rendered at known poses (tests/aruco_render.py: the marker warped onto a background,
blurred, with sensor noise) before timing, then given a colour cast and per-channel noise as **BGR**
frames, what a real camera (cv2.VideoCapture) delivers, so the colour conversion is part of what is
timed on both sides.  Timed on one core (cv2.setNumThreads(1)):

- hilgate: FixedCameraTracker.process(frame) -> vehicle positions in the scene frame (BGR to grey,
  detection, IPPE_SQUARE with both solutions and the flip check, the transforms);
- bare: cvtColor(BGR2GRAY) + ArucoDetector.detectMarkers + solvePnP(IPPE_SQUARE) per marker, nothing else.

Bare and hilgate alternate over the same frames, ``--repeats`` times.  Printed: frames per second of
each (median), hilgate's overhead over bare OpenCV as min/median/max over the repeats (target
<= 10 %), and the position error distribution at 1-2 m (target <= 1 cm at p95).

    python benchmarks/aruco.py [--frames 200] [--repeats 3]
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
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
        frames.append(bgr(render(placed, seed=i), rng))
        truths.append({marker: tvec for marker, _, tvec in placed})
    return frames, truths


def bgr(grey: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A 3-channel uint8 BGR frame from a rendered grey one: a bluish-green underwater cast and each
    channel's own sensor noise (so the channels differ, as a camera's do)."""
    cast = np.array([1.08, 1.0, 0.82])  # B, G, R
    frame = grey[..., None].astype(np.float32) * cast + rng.normal(0, 1.5, grey.shape + (3,))
    return np.clip(frame, 0, 255).astype(np.uint8)


def frames_per_second(function, frames) -> float:
    start = time.perf_counter()
    for frame in frames:
        function(frame)
    return len(frames) / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3, help="alternating bare / hilgate passes over the frames")
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
            corners, ids, _ = detector.detectMarkers(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY))
            for c in corners if ids is not None else ():
                cv2.solvePnP(object_points, c.reshape(4, 2), K_720P, None, flags=cv2.SOLVEPNP_IPPE_SQUARE)

        assert frames[0].ndim == 3 and frames[0].shape[2] == 3
        fps_bare, fps_hilgate = [], []
        for repeat in range(args.repeats):
            order = [(fps_bare, bare), (fps_hilgate, tracker.process)]
            for results, function in (order if repeat % 2 == 0 else order[::-1]):
                results.append(frames_per_second(function, frames))
        overheads = [100 * (b / h - 1) for b, h in zip(fps_bare, fps_hilgate)]
        errors = []
        for frame, truth in zip(frames, truths):
            for sighting in tracker.process(frame):
                errors.append(1000 * math.dist(sighting.position, truth[int(sighting.vehicle[1:])]))
        errors.sort()
        found = len(errors) / (len(frames) * markers)
        print(f"{markers} marker{'s' if markers > 1 else ' '}, BGR {frames[0].shape[1]}x{frames[0].shape[0]}: hilgate "
              f"{statistics.median(fps_hilgate):6.1f} frames/s, bare OpenCV {statistics.median(fps_bare):6.1f} frames/s "
              f"(medians of {args.repeats}); overhead min/median/max {min(overheads):.1f} / "
              f"{statistics.median(overheads):.1f} / {max(overheads):.1f} %  (target <= 10 %)")
        print(f"           error at 1-2 m: median {errors[len(errors) // 2]:.1f} mm, p95 "
              f"{errors[int(0.95 * (len(errors) - 1))]:.1f} mm, max {errors[-1]:.1f} mm; {100 * found:.0f} % found "
              f"(target p95 <= 10 mm)")


if __name__ == "__main__":
    main()
