"""Colour proposals of the EM structure search (paper 001, Sec. VI): a door that never moved is proposed where
a wall's colour changes, not where the class colours merely overlap with the wall's paint."""

from __future__ import annotations

import numpy as np

from doorbatch.config import DoorbatchConfig, ObjectMapConfig
from doorbatch.pipeline.objectmap.beams import BeamSet
from doorbatch.pipeline.objectmap.em import evaluate
from doorbatch.pipeline.objectmap.model import ClassParams, ObjectMap, Wall
from doorbatch.pipeline.objectmap.search import color_candidates, color_contrast

WALL_PAINT = np.array([205.0, 203.0, 195.0])
WOOD = np.array([150.0, 104.0, 64.0])


def _wall_scene(paint_at: object, seed: int) -> BeamSet:
    """A wall along y = 2 (x from −6 to 6) seen head-on from y = 0, 4,000 beams; each beam's colour is its
    paint under lighting 1 + 0.12·sin(2πx / 7 m) (the simulator's amplitude and period) with noise of 5."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(-5.0, 5.0, 4000)
    n = x.size
    paint = np.stack([paint_at(v) for v in x])  # type: ignore[operator]
    light = 1.0 + 0.12 * np.sin(2 * np.pi * x / 7.0)
    colors = light[:, None] * paint + rng.normal(0.0, 5.0, (n, 3))
    origin = np.stack([x, np.zeros(n)], axis=1)
    return BeamSet(np.zeros(n, dtype=np.int64), origin, np.tile([0.0, 1.0], (n, 1)), np.full(n, 2.0),
                   np.full(n, 20.0), np.ones(n, dtype=bool), colors, 1)


def _candidates_x(beams: BeamSet, classes: ClassParams, config: ObjectMapConfig,
                  walls: list[Wall] | None = None) -> list[float]:
    walls = walls or [Wall(np.array([0.0, 1.0]), 2.0, np.array([[-6.0, 6.0]]))]
    state = evaluate(beams, ObjectMap(walls, [], classes, 1), config)
    return sorted(float(c.hinge[0]) for c in color_candidates(beams, state, config))


def _assert_only_proposed_without_the_contrast_rule(beams: BeamSet, classes: ClassParams) -> None:
    """No colour proposal; without the contrast rule (the old behaviour) the most door-like door-wide
    stretch of the wall is proposed."""
    config = DoorbatchConfig().em
    assert _candidates_x(beams, classes, config) == []
    assert len(_candidates_x(beams, classes, config.model_copy(update={"color_contrast_min_sigmas": 0.0}))) >= 2


def test_a_plain_wall_under_changing_light_proposes_no_door_when_the_classes_overlap() -> None:
    # class colours as EM learned them on a site whose door class came out white-ish (l_corridor seed 5):
    # every beam of the wall's darker stretches is a little more door-like than wall-like
    classes = ClassParams(0.9, np.array([[207.0, 204.0, 194.0], [200.0, 199.0, 191.0]]),
                          np.array([[19.0**2] * 3, [14.0**2] * 3]), True)
    _assert_only_proposed_without_the_contrast_rule(_wall_scene(lambda _x: WALL_PAINT, seed=1), classes)


def test_a_wood_door_in_a_painted_wall_is_proposed_at_its_edges() -> None:
    classes = ClassParams(0.9, np.array([WALL_PAINT, WOOD]), np.array([[20.0**2] * 3, [12.0**2] * 3]), True)
    beams = _wall_scene(lambda x: WOOD if 1.0 <= x <= 1.9 else WALL_PAINT, seed=2)
    xs = _candidates_x(beams, classes, DoorbatchConfig().em)
    assert len(xs) == 2
    np.testing.assert_allclose(xs, [1.0, 1.9], atol=0.05)


def test_color_contrast_ignores_brightness_and_sees_hue() -> None:
    rng = np.random.default_rng(0)
    config = DoorbatchConfig().em
    wall = WALL_PAINT + rng.normal(0.0, 5.0, (300, 3))
    darker_wall = 0.85 * WALL_PAINT + rng.normal(0.0, 5.0, (300, 3))  # the same paint in a shadow
    wood = WOOD + rng.normal(0.0, 5.0, (300, 3))
    assert color_contrast(darker_wall, wall, config) < 1.0
    assert color_contrast(wood, wall, config) > 10.0
    assert color_contrast(wood[:3], wall, config) == 0.0  # too few beams on one side: no contrast seen


def test_a_wall_painted_another_colour_all_along_is_no_door() -> None:
    # an end wall in warm paint, which the broad door class (several door paints) explains better than the
    # wall class: every door-wide window of it is door-like, and none has a colour edge along the wall
    warm = np.array([214.0, 186.0, 140.0])
    classes = ClassParams(0.9, np.array([WALL_PAINT, [170.0, 140.0, 110.0]]), np.array([[8.0**2] * 3, [40.0**2] * 3]),
                          True)
    _assert_only_proposed_without_the_contrast_rule(_wall_scene(lambda _x: warm, seed=3), classes)


def test_a_leaf_that_stands_apart_from_its_wall_is_compared_with_the_wall_near_it() -> None:
    # a wood leaf at y = 1.5 in front of the painted wall (its own wall object, nothing beside it on its line)
    classes = ClassParams(0.9, np.array([WALL_PAINT, WOOD]), np.array([[20.0**2] * 3, [12.0**2] * 3]), True)
    # the main wall is wood too at the mirror image x ∈ [−1.9, −1.0] (proposed itself, on the main wall): the leaf
    # is compared with the wall near its own ends, not with the main wall anywhere or at the mirrored place
    beams = _wall_scene(lambda x: WOOD if 1.0 <= abs(x) <= 1.9 else WALL_PAINT, seed=4)
    leaf = (beams.origin[:, 0] >= 1.0) & (beams.origin[:, 0] <= 1.9)
    beams = BeamSet(beams.pass_index, beams.origin, beams.direction, np.where(leaf, 1.5, 2.0), beams.dmax,
                    beams.hit, beams.color, 1)
    walls = [Wall(np.array([0.0, 1.0]), 2.0, np.array([[-6.0, 6.0]])),
             Wall(np.array([0.0, 1.0]), 1.5, np.array([[-1.95, -0.95]]))]  # s = −x along the tangent (−1, 0)
    xs = [x for x in _candidates_x(beams, classes, DoorbatchConfig().em, walls) if x > 0.0]
    assert len(xs) == 2
    np.testing.assert_allclose(xs, [1.0, 1.9], atol=0.05)

