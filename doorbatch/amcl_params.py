"""Nav2 AMCL parameter files as doorbatch configuration: localize with what nav2_amcl ran with.

A ROS 2 parameter file (``<node>: {ros__parameters: {...}}``, e.g. a Nav2 ``nav2_params.yaml``) given as
``--config`` is read for its ``amcl`` node (at the top level or under one namespace). Each nav2_amcl parameter
becomes the ``localize`` key of the same name, and the ones the file leaves out take nav2_amcl's own defaults
(``AmclNode``'s declared values), so that MCL runs as AMCL would have run from that file. Besides the names:

- ``laser_model_type``: ``likelihood_field`` is AMCL's 1 + Σ pz³ without beam skipping (nav2_amcl ignores
  ``do_beamskip`` for it), ``likelihood_field_prob`` the product of the beams with ``do_beamskip`` as given;
  ``beam`` (the ray-cast model) is not implemented.
- ``robot_model_type``: ``nav2_amcl::DifferentialMotionModel`` / ``nav2_amcl::OmniMotionModel`` (or the older
  ``differential`` / ``omnidirectional``).
- AMCL resamples on every ``resample_interval``-th update without an effective-sample-size test, so
  ``resample_neff_ratio`` becomes 1.0; it skips a beam by the share of the particles that explain it
  (``beam_skip_support: particles``).
- ``base_frame_id``, ``odom_frame_id``, ``global_frame_id`` and ``scan_topic`` set ``frames`` and ``topics``
  only where the file gives them (nav2's default base frame, base_footprint, is often not in a log's tree).
- An initial pose (``set_initial_pose``) is not a config value here: the warning names the ``--init`` to pass.

Other top-level keys that are doorbatch sections are kept and merged over the translation. Only ROS 2 files:
ROS 1 amcl's names differ (``odom_alpha1``, ``laser_z_hit``, ``kld_err``); such a file is a clear error.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from doorbatch.errors import ConfigError

log = logging.getLogger(__name__)

ROS_PARAMETERS = "ros__parameters"
AMCL_NODE = "amcl"

# nav2_amcl AmclNode's declared defaults (navigation2 nav2_amcl/src/amcl_node.cpp), for the parameters that
# change the filter.
NAV2_AMCL_DEFAULTS: dict[str, Any] = {
    "alpha1": 0.2, "alpha2": 0.2, "alpha3": 0.2, "alpha4": 0.2, "alpha5": 0.2,
    "robot_model_type": "nav2_amcl::DifferentialMotionModel",
    "laser_model_type": "likelihood_field",
    "z_hit": 0.5, "z_rand": 0.5, "sigma_hit": 0.2, "laser_likelihood_max_dist": 2.0,
    "laser_max_range": 100.0, "laser_min_range": -1.0, "max_beams": 60,
    "do_beamskip": False, "beam_skip_distance": 0.5, "beam_skip_threshold": 0.3, "beam_skip_error_threshold": 0.9,
    "min_particles": 500, "max_particles": 2000, "pf_err": 0.05, "pf_z": 0.99,
    "recovery_alpha_slow": 0.0, "recovery_alpha_fast": 0.0, "resample_interval": 1,
    "update_min_d": 0.25, "update_min_a": 0.2,
}
# nav2_amcl parameters that are doorbatch localize keys of the same name and meaning.
_SAME_NAME = tuple(k for k in NAV2_AMCL_DEFAULTS if k not in ("robot_model_type", "laser_model_type", "do_beamskip"))
_ROBOT_MODELS = {
    "nav2_amcl::DifferentialMotionModel": "differential", "differential": "differential",
    "nav2_amcl::OmniMotionModel": "omnidirectional", "omnidirectional": "omnidirectional",
}
_FRAMES = {"base_frame_id": "base_link", "odom_frame_id": "odom", "global_frame_id": "map"}
# Parameters of a live node that change nothing offline (publishing, services, timing, the beam model's terms).
_NO_EFFECT_OFFLINE = frozenset({
    "tf_broadcast", "transform_tolerance", "save_pose_rate", "always_reset_initial_pose", "map_topic",
    "first_map_only", "use_sim_time", "bond_heartbeat_period", "introspection_mode", "z_max", "z_short",
    "lambda_short", "initial_pose.z",
})
_INITIAL_POSE = ("set_initial_pose", "initial_pose.x", "initial_pose.y", "initial_pose.yaw")


@dataclass(frozen=True)
class AmclTranslation:
    """A doorbatch config tree made from nav2_amcl parameters, and what the translation says about it."""

    tree: dict[str, Any]
    warnings: list[str] = field(default_factory=list)
    ignored: list[str] = field(default_factory=list)  # known parameters without effect offline


# Parameter names only ROS 1 amcl has (Nav2 renamed them): a file with them is a ROS 1 amcl configuration.
_ROS1_ONLY = frozenset({"odom_model_type", "odom_alpha1", "odom_alpha2", "odom_alpha3", "odom_alpha4", "odom_alpha5",
                        "laser_z_hit", "laser_z_rand", "laser_sigma_hit", "laser_max_beams", "kld_err", "kld_z"})


def refuse_ros1_amcl_file(tree: Mapping[str, Any], source: str) -> None:
    """Raise a clear error for a ROS 1 amcl parameter file (flat, or under an ``amcl`` key).

    Not translated: ROS 1's default ``odom_model_type: diff`` draws its noise with the α-sums as standard deviations
    (not variances), which no setting of Nav2's model reproduces.

    Raises:
        ConfigError: the tree holds ROS 1 amcl parameter names.
    """
    inner = tree.get(AMCL_NODE)
    names = set(tree) | (set(inner) if isinstance(inner, Mapping) else set())
    found = sorted(names & _ROS1_ONLY)
    if found:
        raise ConfigError(f"{source}: a ROS 1 amcl parameter file ({', '.join(found[:3])}, ...); doorbatch reads "
                          "Nav2 (ROS 2) amcl files, whose names are the localize section's (alpha1, z_hit, pf_err)")


def is_ros2_parameter_file(tree: Mapping[str, Any]) -> bool:
    """Whether a YAML tree is a ROS 2 parameter file: some node (at the top or under one namespace) holds
    ``ros__parameters``."""
    return bool(_nodes(tree))


def _nodes(tree: Mapping[str, Any]) -> dict[str, Mapping[str, Any]]:
    """``{node path: its ros__parameters}`` at the top level and one namespace deep."""
    found: dict[str, Mapping[str, Any]] = {}
    for key, value in tree.items():
        if not isinstance(value, Mapping):
            continue
        if isinstance(value.get(ROS_PARAMETERS), Mapping):
            found[str(key)] = value[ROS_PARAMETERS]
            continue
        for inner, node in value.items():
            if isinstance(node, Mapping) and isinstance(node.get(ROS_PARAMETERS), Mapping):
                found[f"{key}/{inner}"] = node[ROS_PARAMETERS]
    return found


def _flatten(params: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested parameter mappings as ROS 2 names them: ``initial_pose: {x: 1}`` → ``initial_pose.x``."""
    flat: dict[str, Any] = {}
    for key, value in params.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(_flatten(value, f"{name}."))
        else:
            flat[name] = value
    return flat


def amcl_parameters(tree: Mapping[str, Any], source: str) -> dict[str, Any]:
    """The ``amcl`` node's parameters (flattened) of a ROS 2 parameter file.

    Raises:
        ConfigError: no node named ``amcl``, or more than one.
    """
    nodes = _nodes(tree)
    amcl = {path: params for path, params in nodes.items() if path.rsplit("/", 1)[-1] == AMCL_NODE}
    if not amcl:
        raise ConfigError(f"{source}: a ROS 2 parameter file without an 'amcl' node (nodes: "
                          f"{', '.join(sorted(nodes))}); doorbatch reads nav2_amcl's parameters only")
    if len(amcl) > 1:
        raise ConfigError(f"{source}: more than one 'amcl' node ({', '.join(sorted(amcl))}); keep one")
    return _flatten(next(iter(amcl.values())))


def translate_amcl_parameters(params: Mapping[str, Any], source: str = "config") -> AmclTranslation:
    """Map nav2_amcl parameters (flat ROS 2 names) onto doorbatch's ``localize``, ``frames`` and ``topics``.

    Raises:
        ConfigError: the beam model, an unknown robot model, or a value of the wrong type.
    """
    given = dict(params)
    merged = {**NAV2_AMCL_DEFAULTS, **{k: v for k, v in given.items() if k in NAV2_AMCL_DEFAULTS}}
    localize: dict[str, Any] = {name: merged[name] for name in _SAME_NAME}
    localize["resample_neff_ratio"] = 1.0  # nav2_amcl resamples every resample_interval updates, no Neff test
    localize["beam_skip_support"] = "particles"  # and counts the particles that explain a beam
    warnings: list[str] = []

    model = str(merged["robot_model_type"])
    if model not in _ROBOT_MODELS:
        raise ConfigError(f"{source}: amcl robot_model_type {model!r}: expected one of {', '.join(_ROBOT_MODELS)}")
    localize["robot_model_type"] = _ROBOT_MODELS[model]

    laser_model = str(merged["laser_model_type"])
    if laser_model == "likelihood_field":
        localize.update(beam_combination="amcl", do_beamskip=False)
        if given.get("do_beamskip") is True:
            warnings.append("amcl do_beamskip: true has no effect with laser_model_type likelihood_field (nav2_amcl "
                            "skips beams only in likelihood_field_prob); beams are not skipped")
    elif laser_model == "likelihood_field_prob":
        localize.update(beam_combination="product", do_beamskip=merged["do_beamskip"])
    elif laser_model == "beam":
        raise ConfigError(f"{source}: amcl laser_model_type 'beam' (the ray-cast model) is not implemented; "
                          "use likelihood_field or likelihood_field_prob")
    else:
        raise ConfigError(f"{source}: amcl laser_model_type {laser_model!r}: expected likelihood_field, "
                          "likelihood_field_prob or beam")

    tree: dict[str, Any] = {"localize": localize}
    frames = {key: str(given[name]).lstrip("/") for name, key in _FRAMES.items() if name in given}
    if frames:
        tree["frames"] = frames
    if "scan_topic" in given:
        topic = str(given["scan_topic"])
        tree["topics"] = {"scan": topic if topic.startswith("/") else f"/{topic}"}

    if given.get("set_initial_pose") is True:
        try:
            x, y, yaw = (float(given.get(f"initial_pose.{k}", 0.0)) for k in ("x", "y", "yaw"))
        except (TypeError, ValueError) as err:
            raise ConfigError(f"{source}: amcl initial_pose must hold numbers x, y, yaw ({err})") from err
        warnings.append(f"amcl set_initial_pose: pass --init {x:g},{y:g},{yaw:g} to start there "
                        f"(yaw {math.degrees(yaw):.1f}°); the config does not choose the start")
    known = set(NAV2_AMCL_DEFAULTS) | set(_FRAMES) | _NO_EFFECT_OFFLINE | set(_INITIAL_POSE) | {"scan_topic"}
    unknown = sorted(k for k in given if k not in known)
    if unknown:
        warnings.append(f"amcl parameter(s) not known to doorbatch, ignored: {', '.join(unknown)}")
    ignored = sorted(k for k in given if k in _NO_EFFECT_OFFLINE)
    return AmclTranslation(tree, warnings, ignored)


def translate_ros2_parameter_file(tree: Mapping[str, Any], source: str) -> AmclTranslation:
    """The translation of a ROS 2 parameter file's ``amcl`` node; its warnings are logged."""
    translation = translate_amcl_parameters(amcl_parameters(tree, source), source)
    for message in translation.warnings:
        log.warning("%s: %s", source, message)
    log.info("%s: nav2_amcl parameters translated into localize/frames/topics%s", source,
             f" (no effect offline: {', '.join(translation.ignored)})" if translation.ignored else "")
    return translation
