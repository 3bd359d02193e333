"""The configuration tree: frozen pydantic models with ``extra="forbid"`` at every level.

The defaults live in these models (so an installed package needs no data file); ``configs/default.yaml``
is their dump and a test keeps the two equal. ``load_config`` merges, in order: the defaults, a user YAML
file, a dataset's ``config:`` block, then ``--set section.key=value`` overrides. Any unknown key is a
:class:`~doorbatch.errors.ConfigError` naming the full key path and the closest valid key.
"""

from __future__ import annotations

import difflib
import hashlib
import json
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from doorbatch.errors import ConfigError


class Section(BaseModel):
    """Base of every config section: frozen, unknown keys forbidden."""

    model_config = ConfigDict(extra="forbid", frozen=True)


class TopicsConfig(Section):
    """Topic-role overrides. ``None`` means: detect by message type and the names of DESIGN.md."""

    scan: str | None = None
    odometry: str | None = None
    reference: str | None = None
    transforms: list[str] | None = None
    colors: str | None = None
    image: str | None = None
    camera_info: str | None = None
    detections: str | None = None


class FramesConfig(Section):
    """REP 105 frame names."""

    map: str = "map"
    odom: str = "odom"
    base_link: str = "base_link"


class IoConfig(Section):
    """Reading logs."""

    # A gap between consecutive messages of one topic longer than this many nominal periods is reported.
    gap_factor: float = Field(5.0, gt=1.0)
    # Transforms farther than this outside the buffered time span are an error instead of a clamp.
    tf_extrapolation_limit_s: float = Field(0.1, ge=0.0)
    # A scan in a frame with no transform to base_link is an error unless this says to assume identity.
    assume_identity_laser_tf: bool = False
    # Pair images/detections/colors with scans by nearest stamp within this tolerance.
    stamp_tolerance_s: float = Field(0.05, ge=0.0)
    # CARMEN: laser field of view when 180/181 or 360/361 readings are given (paper-era SICK scanners).
    carmen_fov_deg: float = Field(180.0, gt=0.0, le=360.0)
    # CARMEN: maximum range used when the log gives none and no reading exceeds it.
    carmen_default_max_range_m: float = Field(80.0, gt=0.0)
    # CARMEN: range_min of the scans (the logs give none; their readings are never 0).
    carmen_range_min_m: float = Field(0.0, ge=0.0)
    # CARMEN: nominal scan period used to synthesize stamps when the logged ones are unusable.
    carmen_scan_period_s: float = Field(0.2, gt=0.0)


class LaserConfig(Section):
    """Laser conventions: how no-return beams and short ranges are treated."""

    # A +inf or ≥ range_max beam clears free space up to this distance (m); 0 disables clearing.
    no_return_clear_m: float = Field(5.0, ge=0.0)
    # Keep every n-th beam when a stage decimates scans.
    beam_stride: int = Field(1, ge=1)


class ScanMatchConfig(Section):
    """Config section ``scanmatch`` (frozen, unknown keys forbidden)."""

    # Each scan is voxel-downsampled before matching (one centroid per voxel; evens out the beam density).
    scan_voxel_m: float = Field(0.05, gt=0.0)
    # Submap: the last K keyframes in the map frame, voxel-downsampled (one centroid per voxel).
    submap_keyframes: int = Field(10, ge=1)
    submap_voxel_m: float = Field(0.05, gt=0.0)
    # A scan becomes a keyframe when it moved or turned this much since the last keyframe.
    keyframe_min_d_m: float = Field(0.3, ge=0.0)
    keyframe_min_a_deg: float = Field(10.0, ge=0.0)
    # Correlative search (Olson 2009): window half-widths around the prior, yaw step; x/y step = grid cell.
    correlative_window_m: float = Field(0.5, ge=0.0)
    correlative_window_deg: float = Field(15.0, ge=0.0)
    correlative_step_deg: float = Field(1.0, gt=0.0)
    # The search scores an evenly strided subset of at most this many scan points (PLICP uses them all).
    correlative_max_points: int = Field(200, ge=1)
    grid_resolution_m: float = Field(0.05, gt=0.0)
    grid_sigma_m: float = Field(0.05, gt=0.0)
    coarse_cells: int = Field(6, ge=1)
    # Point-to-line ICP (Censi 2008).
    icp_max_iterations: int = Field(30, ge=1)
    max_correspondence_m: float = Field(0.3, gt=0.0)
    trim_fraction: float = Field(0.9, gt=0.0, le=1.0)
    icp_min_step_m: float = Field(1e-3, gt=0.0)
    icp_min_step_deg: float = Field(0.05, gt=0.0)
    normal_neighbors: int = Field(8, ge=3)
    # Acceptance: fewer inliers, or a smaller dimensionless Hessian eigenvalue, falls back to odometry.
    min_inliers: int = Field(30, ge=3)
    min_degeneracy: float = Field(0.02, ge=0.0)


class MappingConfig(Section):
    """``doorbatch map``: where the poses come from and how logs become passes."""

    # auto: reference if the log has one, else scan matching on odometry (recorded in the manifest).
    pose_source: Literal["auto", "reference", "odometry", "scanmatch"] = "auto"
    # A scan whose pose must be interpolated across a gap longer than this is skipped (with a warning).
    max_pose_gap_s: float = Field(0.5, gt=0.0)
    # Passes after the first must start within this distance of where the previous one's odometry ended
    # when poses come from odometry or scan matching (one odometry frame), else the frames are disjoint.
    odometry_continuity_m: float = Field(1.0, gt=0.0)
    # Split one log into passes at time gaps longer than this (0: one log is one pass).
    split_passes_gap_s: float = Field(0.0, ge=0.0)
    # Integrate every n-th scan (1: all).
    scan_stride: int = Field(1, ge=1)


class DoorbatchConfig(Section):
    """The whole configuration tree."""

    seed: int = 0
    topics: TopicsConfig = TopicsConfig()
    frames: FramesConfig = FramesConfig()
    io: IoConfig = IoConfig()
    laser: LaserConfig = LaserConfig()
    scanmatch: ScanMatchConfig = ScanMatchConfig()
    mapping: MappingConfig = MappingConfig()

    def as_dict(self) -> dict[str, Any]:
        """The resolved tree as plain data (what goes into manifests)."""
        return self.model_dump(mode="json")

    def hash(self) -> str:
        """SHA-256 of the resolved tree in canonical JSON: equal configs hash equally."""
        return tree_hash(self.as_dict())


def tree_hash(tree: Mapping[str, Any]) -> str:
    """SHA-256 of a config tree (plain data) in canonical JSON."""
    text = json.dumps(tree, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def default_config_yaml() -> str:
    """The default tree as YAML (``doorbatch config --dump``, and ``configs/default.yaml``)."""
    return yaml.safe_dump(DoorbatchConfig().as_dict(), sort_keys=False)


def deep_merge(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    """Merge ``over`` into a copy of ``base``; mappings merge key by key, anything else replaces."""
    merged = dict(base)
    for key, value in over.items():
        if isinstance(value, Mapping) and isinstance(merged.get(key), Mapping):
            merged[key] = deep_merge(merged[key], value)
        else:
            merged[key] = value
    return merged


def parse_override(text: str) -> dict[str, Any]:
    """Turn ``section.key=value`` into a nested mapping; the value is parsed as YAML (typed)."""
    if "=" not in text:
        raise ConfigError(f"--set {text!r}: expected section.key=value")
    path, _, raw = text.partition("=")
    keys = [k for k in path.strip().split(".") if k]
    if not keys:
        raise ConfigError(f"--set {text!r}: empty key")
    try:
        value: Any = yaml.safe_load(raw) if raw.strip() else ""
    except yaml.YAMLError as err:
        raise ConfigError(f"--set {text!r}: value is not valid YAML: {err}") from err
    nested: dict[str, Any] = {keys[-1]: value}
    for key in reversed(keys[:-1]):
        nested = {key: nested}
    return nested


def read_yaml_mapping(path: Path) -> dict[str, Any]:
    """Read a YAML file that must hold a mapping (an empty file is an empty mapping)."""
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as err:
        raise ConfigError(f"{path}: cannot read config: {err.strerror or err}") from err
    except yaml.YAMLError as err:
        raise ConfigError(f"{path}: not valid YAML: {err}") from err
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: config must be a mapping of sections, got {type(data).__name__}")
    return data


def _valid_keys(model: type[BaseModel], path: tuple[str | int, ...]) -> list[str]:
    """The field names valid at ``path`` (a path of names into nested models)."""
    current: type[BaseModel] = model
    for part in path:
        field = current.model_fields.get(str(part))
        if field is None:
            return []
        annotation = field.annotation
        if isinstance(annotation, type) and issubclass(annotation, BaseModel):
            current = annotation
        else:
            return []
    return list(current.model_fields)


def _explain(err: ValidationError, source: str) -> ConfigError:
    """One readable message for the first problem pydantic found."""
    first = err.errors()[0]
    loc = tuple(first["loc"])
    key = ".".join(str(p) for p in loc)
    if first["type"] == "extra_forbidden":
        valid = _valid_keys(DoorbatchConfig, loc[:-1])
        close = difflib.get_close_matches(str(loc[-1]), valid, n=1, cutoff=0.0)
        parent = ".".join(str(p) for p in loc[:-1])
        hint = f"; did you mean {'.'.join([parent, close[0]]) if parent else close[0]!r}?" if close else ""
        return ConfigError(f"{source}: unknown config key {key!r}{hint}")
    return ConfigError(f"{source}: config key {key!r}: {first['msg']} (got {first.get('input')!r})")


def load_config(
    config_file: Path | None = None,
    overrides: Iterable[str] = (),
    extra: Mapping[str, Any] | None = None,
) -> DoorbatchConfig:
    """Resolve the configuration: defaults < ``config_file`` < ``extra`` < ``overrides``.

    Raises:
        ConfigError: unreadable file, bad YAML, unknown key (with the closest valid one), wrong type.
    """
    tree: dict[str, Any] = {}
    source = "config"
    if config_file is not None:
        tree = read_yaml_mapping(config_file)
        source = str(config_file)
    if extra:
        tree = deep_merge(tree, extra)
    for text in overrides:
        tree = deep_merge(tree, parse_override(text))
        source = "config" if config_file is None else source
    try:
        return DoorbatchConfig.model_validate(tree)
    except ValidationError as err:
        raise _explain(err, source) from err
