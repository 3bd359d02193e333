"""ROS map_server maps: a YAML file and the image it names, read and written as map_server does.

YAML fields: ``image`` (path relative to the YAML file), ``resolution`` (m/cell), ``origin`` [x, y, yaw]
(pose of the image's lower-left corner), ``negate`` (0/1), ``occupied_thresh``, ``free_thresh``, ``mode``
(``trinary``, ``scale`` or ``raw``; default trinary). The image's top row is the map's highest y.

Reading follows ROS 1 map_server (image_loader.cpp) for each pixel: ``a`` is the mean of its color
channels (alpha excluded, except in trinary mode, where both map_servers average the alpha channel in with the
colors "to preserve existing behavior": an opaque grey 205 is 217.5, free), ``255 - a`` if negate;
``p = (255 - a) / 255``.

- trinary: p > occupied_thresh → 100, p < free_thresh → 0, else −1.
- scale: as trinary, but in between → ``1 + 98 · (p − free) / (occ − free)`` truncated (1..99), or −1 where
  the pixel is fully transparent.
- raw: the value ``a`` itself where it is 0..100, else −1.

Images: PGM P5 (binary, 8- or 16-bit) and P2 (ASCII) are parsed here; anything else (PNG, BMP, ...) is decoded
by OpenCV. Samples are scaled to 0..255 by their maximum value (maxval, or 65535 for a 16-bit PNG), as the image
libraries map_server uses do. Writing always gives trinary ``.pgm`` P5: occupied 0, free 254, unknown 205
(DESIGN.md, Outputs).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import yaml

from doorbatch.errors import InputDataError
from doorbatch.io.atomic import atomic_path, atomic_write_bytes
from doorbatch.maps import OCCUPIED, UNKNOWN, OccupancyMap

PGM_OCCUPIED = 0
PGM_FREE = 254
PGM_UNKNOWN = 205

UInt8Array = npt.NDArray[np.uint8]
Int8Array = npt.NDArray[np.int8]
FloatArray = npt.NDArray[np.float64]

_PGM_TOKEN = re.compile(rb"(?:\s|#[^\n]*(?:\n|$))*([^\s#]+)")


class MapMode(StrEnum):
    """How map_server turns pixel values into occupancy."""

    TRINARY = "trinary"
    SCALE = "scale"
    RAW = "raw"


@dataclass(frozen=True, slots=True)
class MapYaml:
    """The fields of a map_server YAML file, with ``image`` resolved against the YAML's folder."""

    image: Path
    resolution_m: float
    origin_x_m: float
    origin_y_m: float
    origin_yaw_rad: float
    negate: bool = False
    occupied_thresh: float = 0.65
    free_thresh: float = 0.196
    mode: MapMode = MapMode.TRINARY


# ---------------------------------------------------------------------------------------------- writing


def trinary_image(occupancy: Int8Array, occupied_thresh: float, free_thresh: float) -> UInt8Array:
    """Trinary pixel values of an OccupancyGrid array, in the grid's orientation (row 0 = lowest y).

    Cells with probability ≥ ``occupied_thresh`` → 0, known cells with probability ≤ ``free_thresh`` →
    254, everything else (unknown −1, or in between) → 205.
    """
    probability = occupancy.astype(np.float64) / OCCUPIED
    image = np.full(occupancy.shape, PGM_UNKNOWN, dtype=np.uint8)
    image[(occupancy >= 0) & (probability <= free_thresh)] = PGM_FREE
    image[probability >= occupied_thresh] = PGM_OCCUPIED
    return image


def encode_pgm(image: UInt8Array, comment: str = "") -> bytes:
    """A binary 8-bit PGM (P5) of ``image``, whose row 0 is the picture's top row."""
    if image.ndim != 2 or image.dtype != np.uint8:
        raise ValueError("PGM image must be a 2-D uint8 array")
    height, width = image.shape
    note = f"# {comment}\n" if comment else ""
    header = f"P5\n{note}{width} {height}\n255\n".encode("ascii")
    return header + np.ascontiguousarray(image).tobytes()


def _check_thresholds(occupied_thresh: float, free_thresh: float) -> None:
    """Thresholds that make a trinary image read back as written (205 must read as unknown)."""
    unknown_p = (255 - PGM_UNKNOWN) / 255
    if not (0.0 <= free_thresh < unknown_p < occupied_thresh < 1.0):
        raise ValueError(
            f"need 0 <= free_thresh < {unknown_p:.5f} < occupied_thresh < 1, "
            f"got free_thresh={free_thresh}, occupied_thresh={occupied_thresh}"
        )


def write_map(map: OccupancyMap, yaml_path: Path, *, occupied_thresh: float = 0.65,
              free_thresh: float = 0.196) -> None:
    """Write ``map`` as map_server trinary ``<stem>.yaml`` + ``<stem>.pgm`` beside it, each atomically.

    The PGM is written first, so a YAML file present means its image is complete. The image is flipped
    so that its top row is the map's highest y.

    Args:
        map: The occupancy grid.
        yaml_path: The YAML file to write (``map.yaml``); the image goes to the same stem with ``.pgm``.
        occupied_thresh: Probability at or above which a cell is written occupied; also written to the YAML.
        free_thresh: Probability at or below which a known cell is written free; also written to the YAML.

    Raises:
        ValueError: Thresholds with which the image would not read back as written.
        OSError: A file cannot be written.
    """
    _check_thresholds(occupied_thresh, free_thresh)
    yaml_path = Path(yaml_path)
    pgm_path = yaml_path.with_suffix(".pgm")
    image = np.flipud(trinary_image(map.occupancy, occupied_thresh, free_thresh))
    atomic_write_bytes(pgm_path, encode_pgm(image, f"doorbatch {map.resolution_m:.3f} m/pix"))
    fields: dict[str, Any] = {
        "image": pgm_path.name,
        "resolution": float(map.resolution_m),
        "origin": [float(map.origin_x_m), float(map.origin_y_m), float(map.origin_yaw_rad)],
        "negate": 0,
        "occupied_thresh": float(occupied_thresh),
        "free_thresh": float(free_thresh),
        "mode": MapMode.TRINARY.value,
    }
    with atomic_path(yaml_path) as tmp:
        tmp.write_text(yaml.safe_dump(fields, sort_keys=False, default_flow_style=None), encoding="utf-8")


# ---------------------------------------------------------------------------------------------- reading


def _number(fields: dict[str, Any], key: str, yaml_path: Path, default: float | None = None) -> float:
    """A finite number field (a string such as ``1e-05``, which YAML 1.1 leaves a string, is accepted)."""
    if key not in fields:
        if default is None:
            raise InputDataError(f"map YAML has no {key!r} field", path=yaml_path)
        return default
    value = fields[key]
    try:
        if isinstance(value, bool):
            raise TypeError
        number = float(value)
    except (TypeError, ValueError):
        raise InputDataError(f"map YAML field {key!r} is not a number: {value!r}", path=yaml_path) from None
    if not math.isfinite(number):
        raise InputDataError(f"map YAML field {key!r} is not finite: {value!r}", path=yaml_path)
    return number


def _origin(fields: dict[str, Any], yaml_path: Path) -> tuple[float, float, float]:
    origin = fields.get("origin")
    if not isinstance(origin, list) or len(origin) != 3:
        raise InputDataError(f"map YAML field 'origin' must be [x, y, yaw], got {origin!r}", path=yaml_path)
    x, y, yaw = (_number({"origin": v}, "origin", yaml_path) for v in origin)
    return x, y, yaw


def _load_yaml_mapping(yaml_path: Path) -> dict[str, Any]:
    try:
        fields = yaml.safe_load(yaml_path.read_text(encoding="utf-8"))
    except OSError as err:
        raise InputDataError(f"cannot read map YAML: {err.strerror or err}", path=yaml_path) from err
    except (yaml.YAMLError, UnicodeDecodeError) as err:
        raise InputDataError(f"map YAML is not valid YAML: {err}", path=yaml_path) from err
    if not isinstance(fields, dict):
        raise InputDataError("map YAML must be a mapping of fields", path=yaml_path)
    return fields


def read_map_yaml(yaml_path: Path) -> MapYaml:
    """Parse and check a map_server YAML file (the image path is resolved, not opened).

    Raises:
        InputDataError: Unreadable file, bad YAML, a missing or malformed field (names the file).
    """
    yaml_path = Path(yaml_path)
    fields = _load_yaml_mapping(yaml_path)
    image = fields.get("image")
    if not isinstance(image, str) or not image:
        raise InputDataError("map YAML has no 'image' file name", path=yaml_path)
    resolution = _number(fields, "resolution", yaml_path)
    if resolution <= 0.0:
        raise InputDataError(f"map YAML resolution must be positive, got {resolution}", path=yaml_path)
    negate = fields.get("negate", 0)
    if negate not in (0, 1):
        raise InputDataError(f"map YAML field 'negate' must be 0 or 1, got {negate!r}", path=yaml_path)
    mode = fields.get("mode", MapMode.TRINARY.value)
    if mode not in tuple(MapMode):
        raise InputDataError(f"map YAML mode must be trinary, scale or raw, got {mode!r}", path=yaml_path)
    x, y, yaw = _origin(fields, yaml_path)
    occupied = _number(fields, "occupied_thresh", yaml_path, 0.65)
    free = _number(fields, "free_thresh", yaml_path, 0.196)
    # raw mode reads neither; trinary takes equal thresholds (a binary image), scale divides by their difference
    trinary = mode == MapMode.TRINARY.value
    if mode != MapMode.RAW.value and not (0.0 <= free <= occupied <= 1.0 and (free < occupied or trinary)):
        need = "<=" if trinary else "<"
        raise InputDataError(f"map YAML ({mode} mode) needs 0 <= free_thresh {need} occupied_thresh <= 1, got "
                             f"free_thresh {free}, occupied_thresh {occupied} (swapped?)", path=yaml_path)
    return MapYaml(
        image=yaml_path.parent / image, resolution_m=resolution, origin_x_m=x, origin_y_m=y,
        origin_yaw_rad=yaw, negate=bool(negate), occupied_thresh=occupied, free_thresh=free, mode=MapMode(mode),
    )


def _pgm_header(data: bytes, path: Path) -> tuple[bytes, int, int, int, int]:
    """Magic, width, height, maxval, and the offset just past the header's last token."""
    tokens: list[bytes] = []
    pos = 0
    for _ in range(4):
        match = _PGM_TOKEN.match(data, pos)
        if match is None:
            raise InputDataError("PGM header is truncated", path=path)
        tokens.append(match.group(1))
        pos = match.end()
    try:
        width, height, maxval = (int(t) for t in tokens[1:])
    except ValueError:
        raise InputDataError(f"PGM header is malformed: {b' '.join(tokens)!r}", path=path) from None
    if width <= 0 or height <= 0 or not 0 < maxval < 65536:
        raise InputDataError(f"PGM must have a positive size and a maxval of 1..65535, got {width}x{height} "
                             f"maxval {maxval}", path=path)
    return tokens[0], width, height, maxval, pos


def decode_pgm(data: bytes, path: Path) -> UInt8Array:
    """A PGM (P5 binary or P2 ASCII) as a (height, width) uint8 array, row 0 the top row.

    Samples are scaled to 0..255 by maxval (as SDL_image and GraphicsMagick, which the map_servers use, do); a
    binary PGM with maxval above 255 has two bytes per sample, most significant first (netpbm).

    Raises:
        InputDataError: Not a P2/P5 PGM, truncated, or a sample above maxval (names ``path``).
    """
    magic, width, height, maxval, pos = _pgm_header(data, path)
    count = width * height
    if magic == b"P5":
        width_b = 2 if maxval > 255 else 1
        raster = data[pos + 1 : pos + 1 + count * width_b]  # exactly one whitespace byte follows maxval
        if len(raster) < count * width_b:
            raise InputDataError(f"PGM is truncated: {len(raster) // width_b} of {count} pixels", path=path)
        samples = np.frombuffer(raster, dtype=">u2" if width_b == 2 else np.uint8).astype(np.int64)
    elif magic == b"P2":
        try:
            samples = np.array(data[pos:].split(), dtype=np.int64)
        except ValueError:
            raise InputDataError("ASCII PGM has a non-numeric pixel value", path=path) from None
        if samples.size != count:
            raise InputDataError(f"ASCII PGM has {samples.size} pixels, header says {count}", path=path)
    else:
        raise InputDataError(f"not a PGM image (magic {magic[:2]!r})", path=path)
    if samples.size and (samples.min() < 0 or samples.max() > maxval):
        raise InputDataError(f"PGM pixel values outside 0..{maxval}", path=path)
    return (samples * 255 // maxval).astype(np.uint8).reshape(height, width)


def _decode_other(data: bytes, path: Path) -> UInt8Array:
    """Any image OpenCV reads (PNG, BMP, ...): (H, W), (H, W, 3) or (H, W, 4), 8-bit (a 16-bit image scaled
    to 0..255 by 65535)."""
    import cv2

    image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise InputDataError("not an image OpenCV can decode", path=path)
    if image.dtype == np.uint16:
        return (image.astype(np.int64) * 255 // 65535).astype(np.uint8)
    if image.dtype != np.uint8:
        raise InputDataError(f"map image must be 8- or 16-bit, got {image.dtype}", path=path)
    return np.asarray(image, dtype=np.uint8)


def load_image(path: Path) -> UInt8Array:
    """The pixels of a map image, row 0 the top row: PGM parsed here, other formats by OpenCV.

    Raises:
        InputDataError: Missing, unreadable, or undecodable file (names it).
    """
    try:
        data = Path(path).read_bytes()
    except OSError as err:
        raise InputDataError(f"cannot read map image: {err.strerror or err}", path=path) from err
    if data[:2] in (b"P5", b"P2"):
        return decode_pgm(data, path)
    return _decode_other(data, path)


def _mean_and_opaque(pixels: UInt8Array, alpha_in_mean: bool = False) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    """Per pixel: mean of the color channels (alpha excluded unless ``alpha_in_mean``: trinary mode, as both
    map_servers average it in), and whether alpha is nonzero."""
    if pixels.ndim == 2:
        return pixels.astype(np.float64), np.ones(pixels.shape, dtype=np.bool_)
    channels = pixels.shape[2]
    has_alpha = channels in (2, 4)
    color = pixels[..., : channels - 1] if has_alpha and not alpha_in_mean else pixels
    opaque = pixels[..., -1] > 0 if has_alpha else np.ones(pixels.shape[:2], dtype=np.bool_)
    return color.mean(axis=2, dtype=np.float64), opaque


def pixels_to_occupancy(pixels: UInt8Array, meta: MapYaml) -> Int8Array:
    """map_server's interpretation of the pixels (see the module docstring), in image orientation."""
    mean, opaque = _mean_and_opaque(pixels, alpha_in_mean=meta.mode is MapMode.TRINARY)
    if meta.negate:
        mean = 255.0 - mean
    if meta.mode is MapMode.RAW:
        value = np.trunc(mean)
        return np.where((value >= 0) & (value <= OCCUPIED), value, UNKNOWN).astype(np.int8)
    p = (255.0 - mean) / 255.0
    occupied = p > meta.occupied_thresh
    free = p < meta.free_thresh
    if meta.mode is MapMode.TRINARY:
        return np.select([occupied, free], [OCCUPIED, 0], UNKNOWN).astype(np.int8)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = (p - meta.free_thresh) / (meta.occupied_thresh - meta.free_thresh)
    scaled = np.trunc(1.0 + 98.0 * np.nan_to_num(ratio))
    return np.select([occupied, free, opaque], [OCCUPIED, 0, scaled], UNKNOWN).astype(np.int8)


def as_written(map: OccupancyMap, *, occupied_thresh: float = 0.65, free_thresh: float = 0.196) -> OccupancyMap:
    """``map`` as :func:`write_map` and :func:`read_map` give it back (trinary: 100, 0, −1), without files."""
    meta = MapYaml(Path(), map.resolution_m, map.origin_x_m, map.origin_y_m, map.origin_yaw_rad,
                   occupied_thresh=occupied_thresh, free_thresh=free_thresh)
    occupancy = pixels_to_occupancy(trinary_image(map.occupancy, occupied_thresh, free_thresh), meta)
    return OccupancyMap(occupancy=occupancy, resolution_m=map.resolution_m, origin_x_m=map.origin_x_m,
                        origin_y_m=map.origin_y_m, origin_yaw_rad=map.origin_yaw_rad)


def read_map(yaml_path: Path) -> OccupancyMap:
    """Read a map_server map (YAML + the image it names) into an :class:`OccupancyMap`.

    Raises:
        InputDataError: A bad or missing YAML or image file (the message names which).
    """
    meta = read_map_yaml(yaml_path)
    pixels = load_image(meta.image)
    occupancy = np.flipud(pixels_to_occupancy(pixels, meta))
    return OccupancyMap(
        occupancy=np.ascontiguousarray(occupancy), resolution_m=meta.resolution_m,
        origin_x_m=meta.origin_x_m, origin_y_m=meta.origin_y_m, origin_yaw_rad=meta.origin_yaw_rad,
    )
