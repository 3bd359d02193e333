"""Per-beam colours from a camera (DESIGN: per-beam colour role, second source): each scan's end points are
moved into the camera's optical frame with TF and projected through its CameraInfo (the pinhole model of
:mod:`doorbatch.geometry.camera`, shared with the doorpose stage); the colour is the pixel there in the
image nearest in time. Images stream one at a time: a log of images is never held in memory."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorbatchConfig
from doorbatch.errors import LogContentError, TransformError
from doorbatch.geometry.camera import PinholeCamera, camera_from_info, in_image, project_points, scan_in_camera
from doorbatch.geometry.tf_buffer import TfBuffer
from doorbatch.io.reader import open_log
from doorbatch.records import CameraInfo, Image, Role, Scan

UInt8Array = npt.NDArray[np.uint8]
BoolArray = npt.NDArray[np.bool_]


def _nearest_images(scan_stamps: npt.NDArray[np.int64], image_stamps: npt.NDArray[np.int64], max_offset_ns: int
                    ) -> npt.NDArray[np.int64]:
    """For each scan, the index of the image nearest in time (−1 when none is within ``max_offset_ns``)."""
    if image_stamps.size == 0:
        return np.full(scan_stamps.shape[0], -1, dtype=np.int64)
    order = np.argsort(image_stamps, kind="stable")
    sorted_stamps = image_stamps[order]
    pos = np.clip(np.searchsorted(sorted_stamps, scan_stamps), 1, max(sorted_stamps.size - 1, 1))
    left = np.clip(pos - 1, 0, sorted_stamps.size - 1)
    right = np.clip(pos, 0, sorted_stamps.size - 1)
    pick = np.where(np.abs(sorted_stamps[left] - scan_stamps) <= np.abs(sorted_stamps[right] - scan_stamps),
                    left, right)
    near = np.abs(sorted_stamps[pick] - scan_stamps) <= max_offset_ns
    return np.where(near, order[pick], -1).astype(np.int64)


def _image_per_scan(scan_ns: Sequence[int], scan_log_ns: Sequence[int], image_ns: Sequence[int],
                    image_log_ns: Sequence[int], tolerance_ns: int) -> tuple[npt.NDArray[np.int64], str | None]:
    """For each scan the image whose header stamp is nearest its own within ``tolerance_ns``, else the image
    logged nearest it within that (−1: none). Header stamps pair only where the images' stamps keep the scans'
    clock (their medians of stamp − log time within ``tolerance_ns``: a laser stamping with its own clock, a
    camera with another, pair by log time); an unset stamp (0) pairs by log time. Then, when no scan found its
    image by stamp, why (for a warning), else None."""
    scans, scan_log = np.asarray(scan_ns, dtype=np.int64), np.asarray(scan_log_ns, dtype=np.int64)
    images, image_log = np.asarray(image_ns, dtype=np.int64), np.asarray(image_log_ns, dtype=np.int64)
    by_log = _nearest_images(scan_log, image_log, tolerance_ns)
    set_scans, set_images = scans != 0, images != 0
    if not images.size:
        return by_log, None
    if not (set_scans.any() and set_images.any()):
        return by_log, " (their stamps are unset)"
    lag_scans = float(np.median(scans[set_scans] - scan_log[set_scans]))
    lag_images = float(np.median(images[set_images] - image_log[set_images]))
    if abs(lag_scans - lag_images) > tolerance_ns:
        return by_log, (f" (stamp − log time {lag_scans / 1e9:+.3f} s for the scans, {lag_images / 1e9:+.3f} s for "
                        "the images: a camera or a laser stamping with a clock of its own?)")
    never = np.iinfo(np.int64).min // 4  # far from every stamp, and from the scans' own stand-in below
    by_stamp = _nearest_images(np.where(set_scans, scans, never // 2), np.where(set_images, images, never),
                               tolerance_ns)
    return np.where(by_stamp >= 0, by_stamp, by_log), None if (by_stamp >= 0).any() else ""


def camera_beam_colors(path: Path, scans: Sequence[Scan], tf: TfBuffer, config: DoorbatchConfig,
                       header_stamps_ns: Sequence[int] | None = None, max_offset_s: float = 0.1
                       ) -> tuple[list[UInt8Array] | None, list[BoolArray] | None, list[str]]:
    """(B_i, 3) uint8 colours aligned with each scan and (B_i,) masks of the beams that have one: those
    whose end point projects into the image nearest in time (within ``max_offset_s``); None and None when no
    beam has one. Then notes on why the camera colours no beam or colours them doubtfully (a camera on its own
    clock, a CameraInfo that cannot be used or describes another image size, a frame whose z axis is not the
    optical axis, no transform to the camera), for the log's warnings: colour is an optional input, so none of
    these is an error.

    A scan takes the image nearest its header stamp (``header_stamps_ns``, the scans' own before they were
    retimed; default their stamps); where no image's header stamp is that near (a stamp unset, a camera on a
    clock of its own), the image logged nearest it. Two passes over the image topic: stamps first, then each
    image colours the scans that chose it.
    """
    with open_log(path, config) as reader:
        topic = reader.roles.topic(Role.IMAGE) or "the image topic"
        images = [(item.record.stamp_ns, item.record.log_time_ns) for item in reader.messages([Role.IMAGE])
                  if isinstance(item.record, Image)]
    header = [s.stamp_ns for s in scans] if header_stamps_ns is None else list(header_stamps_ns)
    choice, away = _image_per_scan(header, [s.log_time_ns for s in scans], [t for t, _ in images],
                                   [g for _, g in images], int(max_offset_s * 1e9))
    notes: list[str] = []
    if away is not None:
        if not (choice >= 0).any():
            return None, None, [f"no image on {topic} lies within {max_offset_s:g} s of a scan{away}; {COLORLESS}"]
        notes.append(f"no image on {topic} pairs with a scan by header stamp{away}: each scan takes the image "
                     "logged nearest it")
    colors = [np.zeros((s.ranges.shape[0], 3), dtype=np.uint8) for s in scans]
    valid = [np.zeros(s.ranges.shape[0], dtype=bool) for s in scans]
    info: CameraInfo | None = None
    camera: PinholeCamera | None = None  # built once, from the first CameraInfo (the one used throughout)
    frame = ""
    reached = False  # a transform from the laser to the camera was found for some scan
    k = -1
    with open_log(path, config) as reader:
        for item in reader.messages([Role.CAMERA_INFO, Role.IMAGE]):
            rec = item.record
            if isinstance(rec, CameraInfo):
                info = info or rec
                continue
            if not isinstance(rec, Image):
                continue
            k += 1
            users = np.flatnonzero(choice == k)
            if users.size == 0 or info is None:
                continue
            pixels = rec.pixels if rec.pixels.ndim == 3 else np.repeat(rec.pixels[:, :, None], 3, axis=2)
            if camera is None:
                try:
                    camera = camera_from_info(info)
                except LogContentError as err:
                    return None, None, [f"{err.reason}; {COLORLESS}"]
                if (pixels.shape[1], pixels.shape[0]) != (camera.width, camera.height):
                    return None, None, [f"the images on {topic} are {pixels.shape[1]}×{pixels.shape[0]} but their "
                                        f"CameraInfo describes {camera.width}×{camera.height} (a calibration of "
                                        f"another resolution): their pixels would colour the wrong beams; "
                                        f"{COLORLESS}"]
                frame = rec.frame_id or info.frame_id
                notes += [n for n in [_optical_axis_note(tf, frame, scans[int(users[0])])] if n]
            for i in users.tolist():
                reached |= _scan_colors(scans[i], tf, camera, pixels, rec.frame_id or info.frame_id, colors[i],
                                        valid[i])
    if not any(v.any() for v in valid):
        why = ("no CameraInfo arrives before an image" if info is None else
               f"no transform from the laser frame {scans[0].frame_id!r} to the camera frame {frame!r}"
               if camera is not None and not reached else
               f"none of the laser's end points lies in front of the camera frame {frame!r} and inside its image"
               + ("" if notes else " (is its z axis the optical axis, with x right and y down?)"))
        return None, None, [*notes, f"{why}; {COLORLESS}"]
    return colors, valid, notes


COLORLESS = ("the scans get no colours from the camera, so doorbatch map's default stages leave out the em stage "
             "(--stages grid,em runs it on shape and motion alone)")
VERTICAL_AXIS_COS = math.cos(math.radians(30.0))  # an optical axis within 30° of the vertical sees floor or ceiling


def _optical_axis_note(tf: TfBuffer, camera_frame: str, scan: Scan) -> str | None:
    """A note when the camera frame's z axis (the optical axis of a CameraInfo's frame) stands within 30° of the
    laser's vertical: a camera_link-style frame (x forward, z up) given where the optical frame belongs."""
    try:
        rotation = tf.lookup(scan.frame_id, camera_frame, scan.stamp_ns, hold_constant=True)[:3, :3]
    except TransformError:
        return None
    if abs(rotation[2, 2]) < VERTICAL_AXIS_COS:
        return None
    return (f"the camera frame {camera_frame!r} has its z axis {'up' if rotation[2, 2] > 0 else 'down'}: a "
            "CameraInfo's frame is the optical frame (z forward along the optical axis, x right, y down), which a "
            "camera_link-style frame (x forward, z up) is not")


def _scan_colors(scan: Scan, tf: TfBuffer, camera: PinholeCamera, pixels: UInt8Array, frame: str,
                 out: UInt8Array, valid: BoolArray) -> bool:
    """Fill one scan's beam colours (and their mask) from one image; False when TF does not take the laser to
    the camera at the scan's stamp."""
    try:
        pts, idx = scan_in_camera(scan, tf, frame)
    except TransformError:
        return False
    front = pts[:, 2] > 0.05
    uv = project_points(camera, pts[front])
    inside = in_image(camera, uv)
    cols = np.clip(np.rint(uv[inside, 0]).astype(int), 0, pixels.shape[1] - 1)
    rows = np.clip(np.rint(uv[inside, 1]).astype(int), 0, pixels.shape[0] - 1)
    beams = idx[front][inside]
    out[beams] = pixels[rows, cols, :3]
    valid[beams] = True
    return True
