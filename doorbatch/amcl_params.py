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
  (``beam_skip_support: particles``); its recovery averages the weights per particle weighed
  (``recovery_average_per_particle``: ``pf_update_sensor``'s ``w_avg /= set->sample_count``); and it publishes
  the mean of its heaviest cluster of particles (``pose_estimate: heaviest_cluster``). It weighs every particle at
  its own pose, also while the cloud is spread (``global_smoothing: false``: no region-averaged, tempered
  weighting), and a global start draws ``max_particles`` (``pf_init_model``; ``global_particles``). Its map holds
  obstacles at 100 and free cells at 0 only (``convertMap``: ``map_occupied_at_least``, ``map_free_at_most``).
- Values the node replaces at start (a negative ``laser_likelihood_max_dist``, ``max_particles`` or
  ``min_particles``, ``resample_interval`` below 1, ``min_particles`` above ``max_particles``) are replaced the
  same way, with the node's warning.
- ``base_frame_id``, ``odom_frame_id``, ``global_frame_id`` and ``scan_topic`` set ``frames`` and ``topics``
  only where the file gives them (nav2's default base frame, base_footprint, is often not in a log's tree).
- An initial pose (``set_initial_pose``) is not a config value here: the warning names the ``--init`` to pass.

Other top-level keys that are doorbatch sections are kept and merged over the translation.

ROS 1 amcl (navigation's ``amcl_node``) names its parameters differently (``odom_alpha1``, ``laser_z_hit``,
``kld_err``) and has other defaults (``amcl_node.cpp``: 100–5000 particles, z_hit 0.95, resample_interval 2,
recovery 0.001 / 0.1). A ROS 1 parameter tree (flat as a ``<rosparam>`` file, or under an ``amcl`` key as
``rosparam dump`` writes it, or an amcl ``<node>`` of a launch file) is renamed onto the Nav2 names with those
defaults (:func:`translate_ros1_amcl_parameters`):

- ``odom_model_type``: ``diff-corrected`` is Nav2's differential model; ``diff`` (the default) is the same model
  drawing each noise with its α-sum as the standard deviation (``localize.alpha_sums_as_std``); ``omni-corrected``
  / ``omni`` are Nav2's omnidirectional model with α1 and α4 swapped (ROS 1 charges the translation and strafe
  noise from rotation to α1, the rotation noise from rotation to α4; Nav2 the other way round).
- ``selective_resampling: true`` resamples only when Neff < N/2 (``resample_neff_ratio`` 0.5), and injects
  random particles only then (``neff_test_gates_recovery``), as ROS 1's ``pf.c``.
- Values are taken as roscpp's typed ``param()`` takes them (:func:`_roscpp_value`).
- ``initial_cov_xx`` / ``_yy`` / ``_aa`` set the start's spread (``init_sigma_xy_m``, ``init_sigma_yaw_deg``;
  the node's 0.5 m and 15° when not given); ``initial_pose_x`` / ``_y`` / ``_a`` are named in a warning as the
  ``--init`` to pass.
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
    "tf_broadcast", "transform_tolerance", "save_pose_rate", "always_reset_initial_pose", "first_map_only",
    "use_sim_time", "bond_heartbeat_period", "introspection_mode", "z_max", "z_short", "lambda_short", "initial_pose.z",
})
_INITIAL_POSE = ("set_initial_pose", "initial_pose.x", "initial_pose.y", "initial_pose.yaw")


@dataclass(frozen=True)
class AmclTranslation:
    """A doorbatch config tree made from nav2_amcl parameters, and what the translation says about it."""

    tree: dict[str, Any]
    warnings: list[str] = field(default_factory=list)
    ignored: list[str] = field(default_factory=list)  # known parameters without effect offline


# ROS 1 amcl's declared defaults (navigation's amcl/src/amcl_node.cpp, noetic: the node's own private_nh_.param
# values, which its first dynamic_reconfigure call leaves in place), for the parameters that change the filter.
ROS1_AMCL_DEFAULTS: dict[str, Any] = {
    "odom_model_type": "diff",
    "odom_alpha1": 0.2, "odom_alpha2": 0.2, "odom_alpha3": 0.2, "odom_alpha4": 0.2, "odom_alpha5": 0.2,
    "laser_model_type": "likelihood_field",
    "laser_z_hit": 0.95, "laser_z_rand": 0.05, "laser_sigma_hit": 0.2, "laser_likelihood_max_dist": 2.0,
    "laser_max_range": -1.0, "laser_min_range": -1.0, "laser_max_beams": 30,
    "do_beamskip": False, "beam_skip_distance": 0.5, "beam_skip_threshold": 0.3, "beam_skip_error_threshold": 0.9,
    "min_particles": 100, "max_particles": 5000, "kld_err": 0.01, "kld_z": 0.99,
    "recovery_alpha_slow": 0.001, "recovery_alpha_fast": 0.1, "resample_interval": 2, "selective_resampling": False,
    "update_min_d": 0.2, "update_min_a": math.pi / 6.0,
}
# ROS 1 names that Nav2 renamed (the others keep their names).
_ROS1_TO_NAV2 = {
    "odom_alpha1": "alpha1", "odom_alpha2": "alpha2", "odom_alpha3": "alpha3", "odom_alpha4": "alpha4",
    "odom_alpha5": "alpha5", "laser_z_hit": "z_hit", "laser_z_rand": "z_rand", "laser_sigma_hit": "sigma_hit",
    "laser_max_beams": "max_beams", "kld_err": "pf_err", "kld_z": "pf_z",
}
# odom_model_type → (Nav2 robot model, α-sums as standard deviations, α1 and α4 swapped).
_ROS1_ODOM_MODELS = {
    "diff": ("differential", True, False), "diff-corrected": ("differential", False, False),
    "omni": ("omnidirectional", True, True), "omni-corrected": ("omnidirectional", False, True),
}
_ROS1_NO_EFFECT_OFFLINE = frozenset({
    "use_map_topic", "first_map_only", "gui_publish_rate", "save_pose_rate", "transform_tolerance", "tf_broadcast",
    "laser_z_short", "laser_z_max", "laser_lambda_short", "bag_scan_period", "std_warn_level_x", "std_warn_level_y",
    "std_warn_level_yaw", "force_update_after_initialpose", "force_update_after_set_map", "restore_defaults",
})
_ROS1_INITIAL = ("initial_pose_x", "initial_pose_y", "initial_pose_a", "initial_cov_xx", "initial_cov_yy",
                 "initial_cov_aa")
# Parameter names only ROS 1 amcl has (Nav2 renamed them): a flat tree with them is a ROS 1 amcl configuration.
_ROS1_ONLY = frozenset({"odom_model_type", *_ROS1_TO_NAV2})
# Every name a ROS 1 amcl tree may hold: under an ``amcl`` key any of them marks it as one.
_ROS1_KNOWN = frozenset({*ROS1_AMCL_DEFAULTS, *_ROS1_NO_EFFECT_OFFLINE, *_ROS1_INITIAL, *_FRAMES,
                         "beam_skip_error_threshold_"})
# The start's covariance when the node is given none (amcl_node.cpp updatePoseFromServer): 0.5 m, 15°.
_ROS1_INITIAL_COV = {"initial_cov_xx": 0.25, "initial_cov_yy": 0.25, "initial_cov_aa": (math.pi / 12.0) ** 2}


def ros1_amcl_parameters(tree: Mapping[str, Any]) -> dict[str, Any] | None:
    """The ROS 1 amcl parameters of a YAML tree, or None when it holds none: flat (a ``<rosparam>`` file loaded
    into the node, told by a name only ROS 1 has), under an ``amcl`` key, or under ``NAMESPACE: {amcl: ...}``
    (``rosparam dump``).

    Raises:
        ConfigError: more than one ``amcl`` mapping holds ROS 1 names.
    """
    found: list[Mapping[str, Any]] = []
    if set(tree) & _ROS1_ONLY:
        found.append(tree)
    for key, value in tree.items():
        if not isinstance(value, Mapping):
            continue
        inner = [value] if key == AMCL_NODE else [v for k, v in value.items() if k == AMCL_NODE]
        found += [m for m in inner if isinstance(m, Mapping) and set(m) & _ROS1_KNOWN]
    if len(found) > 1:
        raise ConfigError("more than one set of ROS 1 amcl parameters in one file; keep one")
    return dict(found[0]) if found else None


def _roscpp_value(name: str, value: Any, default: Any) -> tuple[Any, str | None]:
    """``value`` as amcl_node's ``private_nh_.param(name, x, default)`` takes it (roscpp): a double from an int or
    a double, an int from an int or a rounded double, a bool from a bool only, a string from a string; else the
    default, with a warning."""
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, float):
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        value = float(value) if ok else value
    elif isinstance(default, int):
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        value = round(value) if ok else value
    else:
        ok = isinstance(value, str)
    if ok:
        return value, None
    return default, (f"amcl {name}: {value!r} is not a {type(default).__name__}; amcl_node ignores it and runs with "
                     f"its default {default!r}")


def _rclcpp_value(name: str, value: Any, default: Any, source: str) -> tuple[Any, str | None]:
    """``value`` as nav2_amcl's declared parameter of ``default``'s type takes it: rclcpp refuses to start on a
    value of another type, and so does doorbatch (a string or a bool for a number, a number for a bool); an
    integer for a double is taken as that double, with a note that the node would refuse it (and an integral double
    for an integer as that integer).

    Raises:
        ConfigError: a value of the wrong type.
    """
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, int | float):
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        if ok and isinstance(default, float) and isinstance(value, int):
            return float(value), (f"amcl {name}: {value!r} is an integer where nav2_amcl declares a double "
                                  f"(rclcpp refuses it at start-up: write {float(value)!r}); taken as "
                                  f"{float(value)!r}")
        if ok and isinstance(default, int) and not isinstance(value, int):
            ok = float(value).is_integer()
            value = int(value) if ok else value
    else:
        ok = isinstance(value, str)
    if not ok:
        raise ConfigError(f"{source}: amcl {name}: {value!r} is not a {type(default).__name__} (nav2_amcl refuses "
                          f"to start on it; its default is {default!r})")
    return value, None


def translate_ros1_amcl_parameters(params: Mapping[str, Any], source: str = "config") -> AmclTranslation:
    """Map ROS 1 amcl parameters onto doorbatch's ``localize``, ``frames`` and ``topics`` (module docstring):
    typed as roscpp reads them, renamed onto Nav2's names with ROS 1's defaults for what ``params`` leaves out,
    then :func:`translate_amcl_parameters`. ``scan_topic`` (not a ROS 1 parameter): where a launch file sends the
    node's ``scan``.

    Raises:
        ConfigError: an unknown ``odom_model_type``, a start covariance that is not positive, or what
            :func:`translate_amcl_parameters` refuses.
    """
    given = dict(params)
    warnings: list[str] = []
    if "beam_skip_error_threshold_" in given:  # amcl_node reads this name first (its cfg's, bug #790)
        given["beam_skip_error_threshold"] = given.pop("beam_skip_error_threshold_")
    if "restore_defaults" in given:  # only dynamic_reconfigure writes it: a dump of a running node
        warnings.append("a parameter dump of a running amcl: dynamic_reconfigure wrote its own defaults for what "
                        "was not set (recovery_alpha_slow/fast 0, not the 0.001 / 0.1 the node ran with; "
                        "beam_skip_error_threshold_ 0.3, not 0.9); check those values")
    merged = dict(ROS1_AMCL_DEFAULTS)
    for name in given.keys() & ROS1_AMCL_DEFAULTS.keys():
        merged[name], note = _roscpp_value(name, given[name], ROS1_AMCL_DEFAULTS[name])
        warnings += [note] if note else []
    odom_model = str(merged.pop("odom_model_type"))
    if odom_model not in _ROS1_ODOM_MODELS:
        raise ConfigError(f"{source}: amcl odom_model_type {odom_model!r}: expected one of "
                          f"{', '.join(_ROS1_ODOM_MODELS)}")
    robot_model, sums_as_std, swap = _ROS1_ODOM_MODELS[odom_model]
    selective = merged.pop("selective_resampling")
    nav2 = {_ROS1_TO_NAV2.get(k, k): v for k, v in merged.items()}
    if swap:
        nav2["alpha1"], nav2["alpha4"] = nav2["alpha4"], nav2["alpha1"]
    nav2["robot_model_type"] = robot_model
    nav2.update({k: given[k] for k in _FRAMES if k in given})
    if "scan_topic" in given:
        nav2["scan_topic"] = given["scan_topic"]
    core = translate_amcl_parameters(nav2, source)
    localize = dict(core.tree["localize"], alpha_sums_as_std=sums_as_std)
    if selective:  # pf_update_resample: only when Neff < N/2, and no random particles when it does not
        localize.update(resample_neff_ratio=0.5, neff_test_gates_recovery=True)
    warnings += core.warnings
    initial = _ros1_start(given, source, warnings)
    localize["init_sigma_xy_m"] = math.sqrt((initial["initial_cov_xx"] + initial["initial_cov_yy"]) / 2.0)
    localize["init_sigma_yaw_deg"] = math.degrees(math.sqrt(initial["initial_cov_aa"]))
    if any(k in given for k in _ROS1_INITIAL[:3]):
        x, y, yaw = (initial.get(k, 0.0) for k in _ROS1_INITIAL[:3])
        warnings.append(_start_hint("initial_pose_x/y/a", x, y, yaw))
    warnings += _unknown(given, set(_ROS1_KNOWN))
    tree = dict(core.tree, localize=localize)
    return AmclTranslation(tree, warnings, sorted(k for k in given if k in _ROS1_NO_EFFECT_OFFLINE))


def _ros1_start(given: Mapping[str, Any], source: str, warnings: list[str]) -> dict[str, float]:
    """initial_pose_* and initial_cov_* as amcl_node takes them: the covariances' defaults (0.5 m, 15°) where
    not given, a NaN ignored with a warning (as the node does).

    Raises:
        ConfigError: a value that is not a number, or a covariance that is not positive.
    """
    out = dict(_ROS1_INITIAL_COV)
    for name in _ROS1_INITIAL:
        if name not in given:
            continue
        value = given[name]
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{source}: amcl {name} must be a number, got {value!r}")
        if math.isnan(value):
            warnings.append(f"amcl {name} is NaN: ignored, as amcl_node does")
            continue
        if name.startswith("initial_cov") and value <= 0.0:
            raise ConfigError(f"{source}: amcl {name} must be positive here (a start spread), got {value!r}")
        out[name] = float(value)
    return out


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
    typed = {k: _rclcpp_value(k, v, NAV2_AMCL_DEFAULTS[k], source) for k, v in given.items() if k in NAV2_AMCL_DEFAULTS}
    merged = {**NAV2_AMCL_DEFAULTS, **{k: v for k, (v, _) in typed.items()}}
    warnings: list[str] = [note for _, note in typed.values() if note] + _substitute_as_amcl_node(merged)
    localize: dict[str, Any] = {name: merged[name] for name in _SAME_NAME}
    localize["resample_neff_ratio"] = 1.0  # nav2_amcl resamples every resample_interval updates, no Neff test
    localize["beam_skip_support"] = "particles"  # and counts the particles that explain a beam
    localize["recovery_average_per_particle"] = True  # pf_update_sensor: w_avg /= set->sample_count
    localize["pose_estimate"] = "heaviest_cluster"  # amcl publishes its heaviest cluster's mean
    localize["global_smoothing"] = False  # amcl weighs each particle at its own pose, never a region's average
    localize["global_particles"] = merged["max_particles"]  # pf_init_model: a global start draws max_samples
    localize["map_occupied_at_least"] = 100  # convertMap: a cell of 100 is an obstacle, of 0 free, else unknown
    localize["map_free_at_most"] = 0

    model = str(merged["robot_model_type"])
    if model not in _ROBOT_MODELS:
        raise ConfigError(f"{source}: amcl robot_model_type {model!r}: expected one of {', '.join(_ROBOT_MODELS)}")
    localize["robot_model_type"] = _ROBOT_MODELS[model]

    laser_model = str(merged["laser_model_type"])
    if laser_model == "likelihood_field":
        localize.update(beam_combination="amcl", do_beamskip=False)
        if given.get("do_beamskip") is True:
            warnings.append("amcl do_beamskip: true has no effect with laser_model_type likelihood_field (AMCL "
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
    if "map_topic" in given:  # the OccupancyGrid topic amcl subscribes to: where --map LOG finds the map
        topic = str(given["map_topic"])
        localize["map_topic"] = topic if topic.startswith("/") else f"/{topic}"

    if given.get("set_initial_pose") is True:
        try:
            x, y, yaw = (float(given.get(f"initial_pose.{k}", 0.0)) for k in ("x", "y", "yaw"))
        except (TypeError, ValueError) as err:
            raise ConfigError(f"{source}: amcl initial_pose must hold numbers x, y, yaw ({err})") from err
        warnings.append(_start_hint("set_initial_pose", x, y, yaw))
    warnings += _unknown(given, set(NAV2_AMCL_DEFAULTS) | _NO_EFFECT_OFFLINE | set(_INITIAL_POSE))
    ignored = sorted(k for k in given if k in _NO_EFFECT_OFFLINE)
    return AmclTranslation(tree, warnings, ignored)


# AmclNode::initParameters' semantic checks: (parameter, is it out of range, the value the node takes instead).
_AMCL_NODE_SUBSTITUTES: tuple[tuple[str, Any, Any], ...] = (
    ("laser_likelihood_max_dist", lambda v: v < 0, 2.0),
    ("max_particles", lambda v: v < 0, 2000),
    ("min_particles", lambda v: v < 0, 500),
    ("resample_interval", lambda v: v <= 0, 1),
)


def _substitute_as_amcl_node(merged: dict[str, Any]) -> list[str]:
    """Replace in ``merged`` the values nav2_amcl's ``initParameters`` replaces (a negative likelihood distance or
    particle count, a resample_interval below 1, min_particles above max_particles: max_particles becomes
    min_particles), as the node does, with its warnings; values that are not numbers are left to the config's
    validation."""
    def number(v: Any) -> bool:
        return isinstance(v, int | float) and not isinstance(v, bool)

    warnings: list[str] = []
    for name, out_of_range, default in _AMCL_NODE_SUBSTITUTES:
        value = merged[name]
        if number(value) and out_of_range(value):
            warnings.append(f"amcl {name}: {value!r} is not allowed; nav2_amcl runs with {default!r} instead, "
                            "and so does this run")
            merged[name] = default
    low, high = merged["min_particles"], merged["max_particles"]
    if number(low) and number(high) and low > high:
        warnings.append(f"amcl min_particles {low!r} > max_particles {high!r}: nav2_amcl sets max_particles to "
                        "min_particles, and so does this run")
        merged["max_particles"] = low
    return warnings


def _start_hint(names: str, x: float, y: float, yaw: float) -> str:
    """The warning for a start pose in a parameter file: the ``--init`` that gives it."""
    return (f"amcl {names}: pass --init {x:g},{y:g},{yaw:g} to start there (yaw {math.degrees(yaw):.1f}°); "
            "the config does not choose the start")


def _unknown(given: Mapping[str, Any], known: set[str]) -> list[str]:
    """A warning naming the parameters neither ``known`` nor frames nor the scan topic, if any."""
    unknown = sorted(k for k in given if k not in known | set(_FRAMES) | {"scan_topic", "map_topic"})
    return [f"amcl parameter(s) not known to doorbatch, ignored: {', '.join(unknown)}"] if unknown else []


def translate_ros2_parameter_file(tree: Mapping[str, Any], source: str) -> AmclTranslation:
    """The translation of a ROS 2 parameter file's ``amcl`` node; its warnings are logged."""
    return logged(translate_amcl_parameters(amcl_parameters(tree, source), source), source, "nav2_amcl")


def logged(translation: AmclTranslation, source: str, origin: str) -> AmclTranslation:
    """``translation``, once its warnings are logged and an info line says what was translated from where."""
    for message in translation.warnings:
        log.warning("%s: %s", source, message)
    log.info("%s: %s parameters translated into localize/frames/topics%s", source, origin,
             f" (no effect offline: {', '.join(translation.ignored)})" if translation.ignored else "")
    return translation
