"""Visitor profiles: what a profile says is drawn the same for every fleet, and a wrong one
is refused with the reason (docs/planning.md, "The profile")."""

from __future__ import annotations

from pathlib import Path

import pytest

from backend.planning.profile import PlanError, draw, load_profile, parse_profile
from tests.planning.test_sim import tiny_site


def test_counts_split_by_shares_add_up_and_the_draw_is_seeded() -> None:
    site = tiny_site()
    profile = parse_profile({"hours": [7, 3], "tours": {"ab": 1.0}, "seed": 4}, site)
    first, again = draw(profile, site), draw(profile, site)
    assert first == again
    assert [sum(1 for r in first if h * 3600 <= r.at < (h + 1) * 3600) for h in (0, 1)] == [7, 3]
    assert all(1 <= r.follow <= 2 for r in first)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"hours": [{"nope": 3}]}, "unknown tour\\(s\\) nope; the site's tours: ab"),
        ({"hours": [3], "tours": {"ab": 1, "gone": 1}}, "unknown tour\\(s\\) gone"),
        ({"hours": [3]}, "hours\\[0\\] is a count; give 'tours' shares"),
        ({"hours": []}, "hours must be a list"),
        ({"hours": [{"ab": -1}]}, "hours\\[0\\].ab must be a count >= 0"),
        (
            {"hours": [{"ab": 1}], "stop_following": 2},
            "stop_following must be a number from 0 to 1",
        ),
        ({"hours": [{"ab": 1}], "crowd": 3}, "unknown key\\(s\\) crowd"),
        ({"hours": [{"ab": 1}], "spacing": "bursty"}, "spacing must be random or even"),
        ([1, 2], "expected a mapping"),
    ],
)
def test_a_wrong_profile_is_refused_saying_why(data: object, message: str) -> None:
    with pytest.raises(PlanError, match=message):
        parse_profile(data, tiny_site())


def test_a_missing_or_broken_file_is_refused(tmp_path: Path) -> None:
    with pytest.raises(PlanError, match=r"profile .*nothing\.yaml: No such file"):
        load_profile(tmp_path / "nothing.yaml", tiny_site())
    broken = tmp_path / "broken.yaml"
    broken.write_text("hours: [1, 2\n", encoding="utf-8")
    with pytest.raises(PlanError, match="not YAML"):
        load_profile(broken, tiny_site())
