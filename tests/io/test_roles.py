"""Which topic plays which role when a log has several candidates."""

from __future__ import annotations

from doorbatch.io import decode as d
from doorbatch.io.roles import TopicInfo, assign_roles
from doorbatch.records import Role


def _topics(*rows: tuple[str, str, int]) -> dict[str, TopicInfo]:
    return {name: TopicInfo(name, msgtype, count, "cdr") for name, msgtype, count in rows}


def test_two_lasers_at_one_rate_read_the_first_by_name_not_the_last() -> None:
    """stage_ros's two lasers, /base_scan_0 (its first: the front) and /base_scan_1, a message apart: the first
    is read, and the note says why; a clearly busier laser still wins whatever its name."""
    tie = assign_roles(_topics(("/base_scan_0", d.LASERSCAN, 584), ("/base_scan_1", d.LASERSCAN, 585)))
    assert tie.topic(Role.SCAN) == "/base_scan_0"
    assert any("first by name of 2 about as busy" in n and "/base_scan_1 not" in n for n in tie.notes)
    busier = assign_roles(_topics(("/base_scan_0", d.LASERSCAN, 300), ("/base_scan_1", d.LASERSCAN, 585)))
    assert busier.topic(Role.SCAN) == "/base_scan_1"
    assert any("most messages of 2" in n for n in busier.notes)


def test_a_reference_is_still_the_busiest_candidate() -> None:
    """The tie rule is the lasers' alone: of two pose topics the busier (then the later name) stays the reference."""
    roles = assign_roles(_topics(("/amcl_pose", d.POSE_COV_STAMPED, 100), ("/base_pose_ground_truth", d.ODOMETRY, 100),
                                 ("/odom", d.ODOMETRY, 100), ("/scan", d.LASERSCAN, 100)))
    assert roles.topic(Role.REFERENCE) == "/base_pose_ground_truth"
    assert roles.topic(Role.ODOMETRY) == "/odom"
