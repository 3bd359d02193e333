"""Issue #7 acceptance of the EM object-map stage (paper 001) on simulated sites with ground truth.

Sites (simulated unless their logs are in ``--work`` already, scenario ``em_mapping``: three passes,
d01..d05 move between passes, the other doors stay closed): A = ``em_corridor`` seed 5 (10 doors),
B = ``em_corridor_b`` seed 6 (8 doors). Reference poses; the default config (every 2nd scan and beam).
``--camera-only``: site A with scenario ``em_mapping_camera`` (colours projected from camera images).
``--sample-only``: the bundled sample (office_corridor seed 1; d02 and d05 never move).

Tables printed (Markdown):
1. Ablation on A (paper 001 Sec. VII): range + colour, range only, colour only (a mixture of two
   Gaussians on all beam colours; the minority component's points clustered into door-sized pieces).
2. Pose noise on A, range only (paper 001 Table 7): Gaussian noise added to every scan's pose.
3. Class transfer: A's learned classes applied to B without relearning (Fig. 5b); B learned alone beside.
4. Walls on A: segment end points against the truth walls' end points on the same line, directions.

A detection matches a truth door when its leaf centres over the passes lie within 0.3 m of the truth
leaf centres on average (greedy, nearest first): the centre, not the hinge, because a door that never
moved shows no hinge (its hinge end is a guess, as the paper says of Fig. 5b).

Usage::

    python scripts/em_acceptance.py [--work DIR] [--json] [--camera-only | --sample-only | --walls-only]
                                    [--em KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import yaml

from doorbatch.config import DoorbatchConfig, ObjectMapConfig
from doorbatch.io.recording import Recording, load_recording
from doorbatch.io.sim_truth import SimTruth, read_truth
from doorbatch.pipeline.gridmap.doors import cluster_points
from doorbatch.pipeline.mapping import PassPoses, pass_poses
from doorbatch.pipeline.objectmap.beams import BeamSet
from doorbatch.pipeline.objectmap.colors import two_gaussian_mixture
from doorbatch.pipeline.objectmap.em import evaluate
from doorbatch.pipeline.objectmap.model import ClassParams
from doorbatch.pipeline.objectmap.prior import log_prior
from doorbatch.pipeline.objectmap.sensor import cast_segments
from doorbatch.pipeline.objectmap.stage import (
    ObjectMapResult,
    build_object_map,
    collect_beams,
    final_step_beams,
    with_strides,
)
from doorbatch.sim.simulate import run_simulation

ROOT = Path(__file__).resolve().parents[1]
MATCH_M = 0.3
NOISE = ((0.0, 0.0), (0.02, 0.3), (0.04, 0.6), (0.06, 0.9))


@dataclass
class Site:
    name: str
    recordings: list[Recording]
    passes: list[PassPoses]
    truth: SimTruth
    truth_centres: np.ndarray  # (D, P, 2)
    moved: np.ndarray  # (D,) bool


def load_site(world: str, seed: int, work: Path, config: DoorbatchConfig, scenario: str = "em_mapping") -> Site:
    folder = work / (f"{world}_seed{seed}" + ("" if scenario == "em_mapping" else f"_{scenario}"))
    if not sorted(folder.glob("map_pass*.mcap")):
        run_simulation(ROOT / "configs" / "worlds" / f"{world}.yaml", folder / "map.mcap", scenario=scenario,
                       seed=seed, split_passes=True)
        (folder / "map.mcap").unlink(missing_ok=True)
    return site_from_folder(f"{world}:{seed}", folder, config)


def site_from_folder(name: str, folder: Path, config: DoorbatchConfig) -> Site:
    """A site from a folder of pass logs ``map_pass*.mcap`` and their truth ``map.truth.yaml``."""
    recs = [load_recording(p, config, with_colors=True) for p in sorted(folder.glob("map_pass*.mcap"))]
    truth = read_truth(folder / "map.truth.yaml")
    mids = np.array([(p.stationary_ns + p.end_ns) // 2 for p in truth.passes], dtype=np.int64)
    angles = np.atleast_2d(truth.door_angles_at(mids))  # (P, D)
    centres = []
    for k, d in enumerate(truth.doors):
        yaw = d.closed_yaw + angles[:, k]
        centres.append(np.array([d.hinge_x, d.hinge_y]) + 0.5 * d.length * np.stack([np.cos(yaw), np.sin(yaw)], 1))
    moved = np.ptp(angles, axis=0) > np.deg2rad(10.0)
    return Site(name, recs, [pass_poses(r, "reference", config) for r in recs], truth, np.array(centres), moved)


def detected_centres(result: ObjectMapResult) -> np.ndarray:
    out = []
    for d in result.doors:
        p = d.preview
        out.append(np.array([p.hinge_x, p.hinge_y]) + 0.5 * p.length * np.stack(
            [np.cos(d.pass_yaws), np.sin(d.pass_yaws)], 1))
    return np.array(out).reshape(-1, len(result.object_map.doors[0].yaws) if result.doors else 1, 2)


def match(det: np.ndarray, truth: np.ndarray) -> tuple[list[tuple[int, int]], list[int]]:
    """Greedy matches (det, truth) by mean centre distance over passes ≤ MATCH_M; unmatched detections."""
    if det.shape[0] == 0:
        return [], []
    if det.ndim == 2:  # one centre per detection (colour only): nearest truth centre over the passes
        dist = np.min(np.linalg.norm(det[:, None, None, :] - truth[None], axis=3), axis=2)
    else:
        dist = np.mean(np.linalg.norm(det[:, None] - truth[None], axis=3), axis=2)
    pairs = sorted((dist[i, j], i, j) for i in range(dist.shape[0]) for j in range(dist.shape[1])
                   if dist[i, j] <= MATCH_M)
    used_d, used_t, out = set(), set(), []
    for _, i, j in pairs:
        if i not in used_d and j not in used_t:
            used_d.add(i)
            used_t.add(j)
            out.append((i, j))
    return out, [i for i in range(det.shape[0]) if i not in used_d]


def score(site: Site, det: np.ndarray) -> dict[str, int]:
    pairs, fp = match(det, site.truth_centres)
    found = {j for _, j in pairs}
    return {"moved_found": sum(1 for j in found if site.moved[j]), "moved": int(site.moved.sum()),
            "still_found": sum(1 for j in found if not site.moved[j]), "still": int((~site.moved).sum()),
            "false_positives": len(fp)}


def run(site: Site, em: ObjectMapConfig, classes: ClassParams | None = None, noise: tuple[float, float] = (0, 0),
        seed: int = 0) -> tuple[ObjectMapResult, BeamSet]:
    passes = site.passes
    if noise[0] > 0:
        rng = np.random.default_rng(seed)
        passes = [replace(p, poses=p.poses + np.column_stack([rng.normal(0, noise[0], (p.poses.shape[0], 2)),
                                                               rng.normal(0, np.deg2rad(noise[1]), p.poses.shape[0])]))
                  for p in passes]
    em = with_strides(site.recordings, em)  # resolved, as the stage does (stride_weighted_prior needs them)
    beams = collect_beams(site.recordings, passes, em)
    return build_object_map(beams, em, classes, final_step_beams(site.recordings, passes, em)), beams


def color_only(site: Site, beams: BeamSet) -> dict[str, int]:
    """The paper's colour-only model: 2 Gaussians on all colours; door-coloured points in door-sized pieces."""
    ok = beams.hit & np.isfinite(beams.color[:, 0])
    mix = two_gaussian_mixture(beams.color[ok])
    door = int(np.argmin(mix.weights))
    pts = beams.points[ok][mix.labels == door]
    labels = cluster_points(pts, 0.1)
    centres = []
    for lab in np.unique(labels):
        q = pts[labels == lab]
        if q.shape[0] < 20:
            continue
        extent = np.sqrt(max(np.linalg.eigvalsh(np.cov(q.T))[-1], 0.0) * 12.0)  # length of a uniform segment
        if 0.5 <= extent <= 1.3:
            centres.append(q.mean(axis=0))
    return score(site, np.array(centres).reshape(-1, 2))


def false_positive_scores(site: Site, result: ObjectMapResult, beams: BeamSet, em: ObjectMapConfig
                          ) -> list[dict[str, object]]:
    """Each unmatched detection: where it is, and what it is worth to the log posterior (the map without it,
    re-evaluated on the kept beams), with the log-likelihood part with and without the colour term."""
    _, fp = match(detected_centres(result), site.truth_centres)
    obj_map, out = result.object_map, []
    if not fp:
        return out
    no_colour = replace(obj_map.classes, has_color=False)
    prior_all = log_prior(obj_map, em)
    post_all = evaluate(beams, obj_map, em).log_posterior
    post_range = evaluate(beams, replace(obj_map, classes=no_colour), em).log_posterior
    for i in fp:
        without = replace(obj_map, doors=obj_map.doors[:i] + obj_map.doors[i + 1:])
        dprior = prior_all - log_prior(without, em)
        d_all = post_all - evaluate(beams, without, em).log_posterior
        d_range = post_range - evaluate(beams, replace(without, classes=no_colour), em).log_posterior
        p = result.doors[i].preview
        out.append({"hinge": [round(p.hinge_x, 2), round(p.hinge_y, 2)],
                    "pass_yaws_deg": np.rad2deg(result.doors[i].pass_yaws).round(0).tolist(),
                    "observed": result.doors[i].pass_observed.tolist(), "moved": p.moved,
                    "d_log_posterior": round(d_all, 1), "d_loglik": round(d_all - dprior, 1),
                    "d_loglik_range_only": round(d_range - dprior, 1), "d_log_prior": round(dprior, 1)})
    return out


def observed_ends(segment: np.ndarray, points: np.ndarray, near_m: float = 0.05, gap_m: float = 0.3,
                  min_points: int = 5) -> np.ndarray:
    """End points of the parts of a truth wall segment the laser actually hit: the hits within ``near_m`` of it,
    projected on it, split where consecutive hits are more than ``gap_m`` apart; parts of fewer than
    ``min_points`` hits are dropped. (K, 2) points."""
    a, b = segment
    length = float(np.linalg.norm(b - a))
    u = (b - a) / length
    rel = points - a
    along, across = rel @ u, rel @ np.array([-u[1], u[0]])
    ts = np.sort(along[(np.abs(across) <= near_m) & (along >= -near_m) & (along <= length + near_m)])
    if ts.size < min_points:
        return np.zeros((0, 2))
    cut = np.flatnonzero(np.diff(ts) > gap_m)
    first, last = np.r_[0, cut + 1], np.r_[cut, ts.size - 1]
    keep = (last - first + 1) >= min_points
    return a + np.outer(np.r_[ts[first[keep]], ts[last[keep]]], u)


def hits_by_truth_segment(beams: BeamSet, segments: np.ndarray, near_m: float = 0.05) -> list[np.ndarray]:
    """The hits each truth wall segment (S, 2, 2) produced: the ray cast against all truth segments meets
    that segment first and the measured range is within ``near_m`` of it. Proximity alone is not enough:
    at a corner the hits on the adjoining wall (e.g. the corridor wall's face at a room wall's end, seen
    from the corridor) lie within a few cm of the room wall's end point but were never reflected by it."""
    hit = np.flatnonzero(beams.hit)
    rng, idx = cast_segments(beams.origin[hit], beams.direction[hit], segments)
    own = np.abs(beams.range_m[hit] - rng) <= near_m
    points = beams.points[hit]
    return [points[own & (idx == k)] for k in range(segments.shape[0])]


def wall_accuracy(site: Site, result: ObjectMapResult, beams: BeamSet | None = None) -> dict[str, dict[str, float]]:
    """EM segment end points on lines that match a truth line (3°, 0.15 m): distance to the nearest truth
    segment end point on that line, and line direction errors; separately for the corridor walls (truth
    kind ``wall``: the robot sees all of them) and the room walls (kind ``room``: seen only through open
    doorways, so their segments end where the view ends, not where the wall does). With ``beams``, also the
    distance to the nearest end of the truth wall's *observed* parts (:func:`observed_ends` of the hits
    :func:`hits_by_truth_segment` gives that wall), and how many truth walls with an observed part have an
    EM line (``seen``, ``mapped``). Pass every scan and beam of the log (``collect_beams(..., strides=(1, 1))``):
    what the laser saw does not depend on the EM's decimation."""
    segs = site.truth.segments
    own_hits = hits_by_truth_segment(beams, segs) if beams is not None else None
    kinds = np.array(site.truth.segment_kinds)
    d = segs[:, 1] - segs[:, 0]
    tn = np.stack([-d[:, 1], d[:, 0]], 1) / np.linalg.norm(d, axis=1, keepdims=True)
    toff = np.sum(tn * segs[:, 0], axis=1)
    out: dict[str, dict[str, float]] = {}
    mapped = np.zeros(segs.shape[0], dtype=bool)
    for kind in ("wall", "room"):
        errs, dirs, seen_errs = [], [], []
        for w in result.object_map.walls:
            c = tn @ w.normal
            same = (np.abs(c) > np.cos(np.deg2rad(3.0))) & (np.abs(toff * np.sign(c) - w.offset) < 0.15)
            if not same.any() or np.mean(kinds[same] == kind) < 0.5:
                continue
            mapped |= same
            dirs.append(np.rad2deg(np.arccos(min(1.0, float(np.max(np.abs(c[same])))))))
            ends = segs[same].reshape(-1, 2)
            errs += [float(np.min(np.linalg.norm(ends - e, axis=1))) for e in w.endpoints().reshape(-1, 2)]
            if own_hits is not None:
                seen = np.concatenate([observed_ends(segs[k], own_hits[k])
                                       for k in np.flatnonzero(same)]).reshape(-1, 2)
                if seen.size:
                    seen_errs += [float(np.min(np.linalg.norm(seen - e, axis=1))) for e in w.endpoints().reshape(-1, 2)]
        e = np.array(errs)
        out[kind] = {"walls": len(dirs), "endpoints": int(e.size),
                     "within_0.10m": float(np.mean(e <= 0.10)) if e.size else float("nan"),
                     "median_m": float(np.median(e)) if e.size else float("nan"),
                     "max_m": float(np.max(e)) if e.size else float("nan"),
                     "max_dir_deg": float(max(dirs)) if dirs else float("nan"),
                     "observed_within_0.10m": (float(np.mean(np.array(seen_errs) <= 0.10)) if seen_errs
                                               else float("nan")),
                     "observed_max_m": float(np.max(seen_errs)) if seen_errs else float("nan")}
        if own_hits is not None:
            seen = np.array([kinds[k] == kind and observed_ends(segs[k], own_hits[k]).size > 0
                             for k in range(segs.shape[0])])
            out[kind] |= {"seen": int(seen.sum()), "mapped": int((seen & mapped).sum())}
    out["all"] = {"em_walls": len(result.object_map.walls)}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", type=Path, default=None)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--sample-only", action="store_true",
                    help="only the bundled sample's mapping passes: range + colour and range only")
    ap.add_argument("--walls-only", action="store_true",
                    help="only site A, range + colour: the wall table (end points against truth and observed parts)")
    ap.add_argument("--camera-only", action="store_true",
                    help="only site A with colours from a camera (scenario em_mapping_camera), range + colour")
    ap.add_argument("--em", action="append", default=[], metavar="KEY=VALUE",
                    help="override an em config field (YAML value), e.g. --em stride_weighted_prior=true")
    args = ap.parse_args()
    config = DoorbatchConfig.model_validate({"em": {k: yaml.safe_load(v) for k, v in
                                                    (a.split("=", 1) for a in args.em)}})
    if args.sample_only:
        sample = site_from_folder("sample", ROOT / "datasets" / "sample" / "logs", config)
        res, beams = run(sample, config.em)
        rows = {"range_color": score(sample, detected_centres(res)),
                "range_only": score(sample, detected_centres(
                    run(sample, config.em.model_copy(update={"use_color": False}))[0])),
                "range_color_false_positives": false_positive_scores(sample, res, beams, config.em)}
        print(json.dumps(rows))
        return
    if args.walls_only:
        with tempfile.TemporaryDirectory() as tmp:
            site = load_site("em_corridor", 5, args.work or Path(tmp), config)
            res, _ = run(site, config.em)
            all_beams = collect_beams(site.recordings, site.passes, config.em, (1, 1))
            print(json.dumps(wall_accuracy(site, res, all_beams), indent=2))
        return
    if args.camera_only:
        with tempfile.TemporaryDirectory() as tmp:
            cam = load_site("em_corridor", 5, args.work or Path(tmp), config, "em_mapping_camera")
            res, beams = run(cam, config.em)
            row = {**score(cam, detected_centres(res)), "coloured_beams": int(np.isfinite(beams.color[:, 0]).sum()),
                   "beams": len(beams), "seconds": res.seconds}
        print(json.dumps(row))
        return
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        a = load_site("em_corridor", 5, work, config)
        b = load_site("em_corridor_b", 6, work, config)
        out: dict[str, object] = {}
        t0 = time.perf_counter()
        full, beams = run(a, config.em)
        out["range_color"] = {**score(a, detected_centres(full)), "seconds": full.seconds, "beams": full.n_beams}
        ronly, _ = run(a, config.em.model_copy(update={"use_color": False}))
        out["range_only"] = {**score(a, detected_centres(ronly)), "seconds": ronly.seconds}
        out["color_only"] = color_only(a, beams)
        noise_rows = []
        for sxy, syaw in NOISE:
            res = ronly if sxy == 0 else run(a, config.em.model_copy(update={"use_color": False}), noise=(sxy, syaw))[0]
            noise_rows.append({"noise_m": sxy, "noise_deg": syaw, **score(a, detected_centres(res))})
        out["pose_noise_range_only"] = noise_rows
        transfer, _ = run(b, config.em, classes=full.object_map.classes)
        alone, _ = run(b, config.em)
        out["transfer_b"] = {**score(b, detected_centres(transfer)),
                             "door_width_m": transfer.object_map.classes.door_width_m}
        out["b_learned_alone"] = score(b, detected_centres(alone))
        out["walls_a"] = wall_accuracy(a, full, collect_beams(a.recordings, a.passes, config.em, (1, 1)))
        out["classes_a"] = {"door_width_m": full.object_map.classes.door_width_m,
                            "wall_rgb": full.object_map.classes.color_mean[0].round(1).tolist(),
                            "door_rgb": full.object_map.classes.color_mean[1].round(1).tolist()}
        out["total_seconds"] = time.perf_counter() - t0
    if args.json:
        print(json.dumps(out, indent=2))
        return
    print("| model (site A, 5 moved + 5 never-moved doors) | moved found | never-moved found | false positives |")
    print("| --- | --- | --- | --- |")
    for key, label in (("range_color", "range + colour"), ("range_only", "range only"),
                       ("color_only", "colour only (2-Gaussian mixture)")):
        r = out[key]
        assert isinstance(r, dict)
        print(f"| {label} | {r['moved_found']}/{r['moved']} | {r['still_found']}/{r['still']} | "
              f"{r['false_positives']} |")
    print("\n| pose noise (cm / deg), range only | doors found (moved) | false positives |\n| --- | --- | --- |")
    for r in noise_rows:
        print(f"| {100 * r['noise_m']:.0f} / {r['noise_deg']:.1f} | {r['moved_found']}/{r['moved']} | "
              f"{r['false_positives']} |")
    print("\n| site B (5 moved + 3 never-moved) | moved found | never-moved found | false positives |")
    print("| --- | --- | --- | --- |")
    for key, label in (("transfer_b", "A's classes, not relearned"), ("b_learned_alone", "learned on B alone")):
        r = out[key]
        assert isinstance(r, dict)
        print(f"| {label} | {r['moved_found']}/{r['moved']} | {r['still_found']}/{r['still']} | "
              f"{r['false_positives']} |")
    print("\n| walls (site A) | lines | end points | within 0.10 m | median | max | max direction error | "
          "within 0.10 m of the observed parts | max from the observed parts | truth walls seen / with an EM line |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    walls = out["walls_a"]
    assert isinstance(walls, dict)
    for kind, label in (("wall", "corridor walls"), ("room", "room walls (seen through doorways)")):
        r = walls[kind]
        print(f"| {label} | {r['walls']} | {r['endpoints']} | {100 * r['within_0.10m']:.0f} % | "
              f"{100 * r['median_m']:.1f} cm | {100 * r['max_m']:.1f} cm | {r['max_dir_deg']:.2f}° | "
              f"{100 * r['observed_within_0.10m']:.0f} % | {100 * r['observed_max_m']:.1f} cm | "
              f"{r['seen']} / {r['mapped']} |")
    print(f"classes (site A): {json.dumps(out['classes_a'])}")
    print(f"seconds: range+colour EM {full.seconds:.1f} ({full.n_beams} beams); all {out['total_seconds']:.0f}")


if __name__ == "__main__":
    main()
