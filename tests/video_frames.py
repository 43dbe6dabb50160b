"""Test helper: a few frames of a real video, for the tests that use ../shared/data."""

from __future__ import annotations

import cv2


def read_frames(path, indices, size=(384, 288)):
    """RGB uint8 frames ``indices`` of a video, area-resized to ``size`` (w, h)."""
    cap = cv2.VideoCapture(str(path))
    frames, k = {}, 0
    while k <= max(indices):
        ok, frame = cap.read()
        assert ok, f"cannot read frame {k} of {path}"
        if k in indices:
            frames[k] = cv2.cvtColor(cv2.resize(frame, size, interpolation=cv2.INTER_AREA), cv2.COLOR_BGR2RGB)
        k += 1
    cap.release()
    return [frames[i] for i in indices]
