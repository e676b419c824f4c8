"""Record the catching camera: a frame server's frames to a lossless video, with the ball's detections.

Usage::

    python -m services.catching.recording --port 7210 --frames 50 --out tests/data/catching_camera.mkv

Grabs frames from a camera frame server (``petrobot sim catching``'s, or a bridge to a real camera),
writes them with :func:`services.devices.capture.record` (FFV1 in Matroska, and the camera's info map
in the JSON beside it) and records, for each live frame, where the threshold locator found the ball
(pixels; ``null`` for none). Played back through ``VideoCapture`` (a camera driver's ``source``), the
recording gives the same detections as those live frames (tests/loopback/test_capture.py), so a lab
can test the vision node on its own camera's recordings offline.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Iterator
from pathlib import Path

from services.catching.camera import VisionConfig
from services.catching.vision import locate_threshold
from services.devices.capture import record
from services.devices.framegrabber import Frame, FrameClient

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    """The command line (module docstring); returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m services.catching.recording", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--host", default="127.0.0.1", help="frame server address (default: %(default)s)")
    parser.add_argument("--port", type=int, default=7210, help="frame server port (default: %(default)s)")
    parser.add_argument("--frames", type=int, default=50, help="frames to record (default: %(default)s)")
    parser.add_argument("--after-ball", action="store_true",
                        help="start with the first frame in which the ball is seen")
    parser.add_argument("--out", required=True, help="the video file (.mkv); its JSON goes beside it")
    args = parser.parse_args(argv)
    client = FrameClient(args.host, args.port)
    try:
        info = client.info()
        roi = VisionConfig.from_info(info).roi

        def frames() -> Iterator[Frame]:
            seq, taken = -1, 0
            while taken < args.frames:
                frame = client.grab(after=seq, timeout=5.0)
                if frame is None:
                    raise ConnectionError("no frame from the camera server for 5 s")
                seq = frame.seq
                if taken == 0 and args.after_ball and locate_threshold(frame.image, frame.t, roi=roi) is None:
                    continue
                taken += 1
                print(f"\rrecorded {taken}/{args.frames}", end="", file=sys.stderr, flush=True)
                yield frame

        def detect(frame: Frame) -> list[float] | None:
            d = locate_threshold(frame.image, frame.t, roi=roi)
            return None if d is None else [d.u, d.v]

        n = record(frames(), args.out, fps=float(info.get("fps", 25.0)), info=info, detect=detect)
    except (OSError, ConnectionError) as exc:
        print(f"\nrecording failed: {exc}", file=sys.stderr)
        return 1
    finally:
        client.close()
    print(f"\n{n} frames in {args.out} ({os.path.getsize(args.out)} bytes) and {Path(args.out).with_suffix('.json')}",
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
