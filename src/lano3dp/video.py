"""Episode videos: MP4 (ffmpeg) or GIF (Pillow), chosen by the file suffix. A bottom-layer utility, so
evaluation writes videos without importing the simulator.

A video is written to a temporary file beside its path and renamed into place only once it is known whole:
for MP4, ffmpeg's exit status and a read-back of the frame count (ffmpeg that cannot write its trailer on a
full disk still leaves a short file, and imageio's writer does not look at its exit status); for a GIF, the
file is opened again. Any failure removes the temporary file and raises `StorageError` naming the path and the
cause, and an older video at the path stays as it was.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from lano3dp.errors import StorageError, describe_os_error
from lano3dp.jsonio import discard

MP4_SUFFIXES = (".mp4", ".m4v", ".mov")


def write_video(path: str | Path, frames: Sequence[np.ndarray], fps: float = 10.0) -> Path:
    """Write (H, W, 3) uint8 frames to `path` (.mp4 or .gif). Returns the path.

    Raises:
        ValueError: no frames, frames of different sizes, or another suffix.
        StorageError: the file could not be written whole (names the path and the cause).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix != ".gif" and suffix not in MP4_SUFFIXES:
        raise ValueError(f"unsupported video suffix {suffix!r} for {path}; use .mp4 or .gif")
    if len(frames) == 0:
        raise ValueError(f"no frames to write to {path}")
    frames = [np.ascontiguousarray(frame, dtype=np.uint8) for frame in frames]
    shapes = {frame.shape for frame in frames}
    if len(shapes) != 1 or len(next(iter(shapes))) != 3 or next(iter(shapes))[2] != 3:
        raise ValueError(f"video frames must all be (H, W, 3), got shapes {sorted(shapes)} for {path}")
    temporary = path.with_name(f".{path.stem}.tmp-{os.getpid()}{suffix}")  # the suffix tells the format
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        if suffix == ".gif":
            _write_gif(temporary, frames, fps)
        else:
            _write_mp4(temporary, frames, fps)
        os.replace(temporary, path)
    except OSError as error:
        discard(temporary)
        if isinstance(error, StorageError):
            raise StorageError(path, error.cause) from error
        raise StorageError(path, describe_os_error(error)) from error
    except BaseException:
        discard(temporary)
        raise
    return path


def _write_mp4(path: Path, frames: list[np.ndarray], fps: float) -> None:
    """H.264 through ffmpeg (the binary imageio-ffmpeg ships), with the options imageio used; small sizes are kept
    as they are (no macro-block rescaling), an odd side gets one black row or column (yuv420p needs even ones)."""
    import imageio_ffmpeg

    height, width = frames[0].shape[:2]
    command = [imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-f", "rawvideo", "-vcodec", "rawvideo", "-s",
               f"{width}x{height}", "-pix_fmt", "rgb24", "-r", f"{fps:g}", "-i", "-", "-an",
               "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-vcodec", "libx264", "-pix_fmt", "yuv420p", "-v", "error",
               str(path)]
    try:
        finished = subprocess.run(command, input=b"".join(frame.tobytes() for frame in frames),
                                  capture_output=True, timeout=600)
    except subprocess.TimeoutExpired as error:
        raise StorageError(path, "ffmpeg did not finish within 600 s") from error
    if finished.returncode < 0:
        raise StorageError(path, f"ffmpeg was stopped by {signal.Signals(-finished.returncode).name}")
    if finished.returncode != 0:
        # its first line names the cause ("Could not write header ...: No space left on device"); drop the
        # "[muxer @ 0x...]" prefix
        messages = [re.sub(r"^(\[[^]]*\]\s*)+", "", line.strip())
                    for line in finished.stderr.decode(errors="replace").splitlines() if line.strip()]
        raise StorageError(path, f"ffmpeg exited with status {finished.returncode}"
                                 + (f": {messages[0]}" if messages else ""))
    written = _count_mp4_frames(path)
    if written != len(frames):
        raise StorageError(path, f"{len(frames)} frames written but {written} read back")


def _count_mp4_frames(path: Path) -> int:
    import imageio_ffmpeg

    try:
        return int(imageio_ffmpeg.count_frames_and_secs(str(path))[0])
    except (RuntimeError, OSError, ValueError):  # ffmpeg could not read it back: nothing whole there
        return 0


def _write_gif(path: Path, frames: list[np.ndarray], fps: float) -> None:
    """An animated GIF through Pillow (imageio's GIF writer reports a failed flush only from its finaliser)."""
    from PIL import Image

    images = [Image.fromarray(frame) for frame in frames]
    images[0].save(path, save_all=True, append_images=images[1:], duration=1000.0 / fps, loop=0)
    try:
        with Image.open(path) as written:
            size, count = written.size, getattr(written, "n_frames", 1)
    except (OSError, ValueError, SyntaxError) as error:  # PIL raises SyntaxError on some malformed headers
        raise StorageError(path, f"the GIF does not read back ({describe_os_error(error)})") from error
    # Pillow merges identical consecutive frames, so the count read back can be lower, never zero
    if size != (frames[0].shape[1], frames[0].shape[0]) or not 1 <= count <= len(frames):
        raise StorageError(path, f"the GIF reads back as {count} frames of {size}, not {len(frames)} of "
                                 f"{frames[0].shape[1]}x{frames[0].shape[0]}")
