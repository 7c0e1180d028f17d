"""Site.robot(), poi(), tour() and module() look up in O(1) and never answer from stale data."""

from __future__ import annotations

import copy
import pickle
from typing import Any

from backend.site.draft import SiteDrafts
from backend.site.service import SiteService
from guidebot.site.building_config import BuildingConfig
from guidebot.site.schema import RobotConfig, Site

from .helpers import demo_site


class CountingList(list[Any]):
    """A list that counts how often it is walked (a scan walks it once per lookup)."""

    def __init__(self, items: list[Any]) -> None:
        super().__init__(items)
        self.walks = 0

    def __iter__(self) -> Any:
        self.walks += 1
        return super().__iter__()


def robots(n: int, prefix: str = "r") -> list[RobotConfig]:
    return [RobotConfig(name=f"{prefix}{i}", token=f"token-{prefix}{i}") for i in range(n)]


def test_a_thousand_lookups_walk_the_list_once() -> None:
    fleet = CountingList(robots(1000))
    site = demo_site().model_copy(update={"robots": fleet})
    for cfg in reversed(fleet[:]):
        assert site.robot(cfg.name) is cfg
    assert site.robot("nobody") is None
    assert fleet.walks == 1  # the table's one build; a scan would have walked it 1001 times
    pois = CountingList(list(site.pois))
    site = site.model_copy(update={"pois": pois})
    for _ in range(100):
        assert site.poi(pois[-1].id) is pois[-1]
    assert pois.walks == 1


def test_the_building_looks_up_modules_once() -> None:
    site = demo_site()
    modules = CountingList(list(site.modules))
    building = BuildingConfig(modules=site.modules).model_copy(update={"modules": modules})
    for _ in range(50):
        assert building.module(modules[-1].id) is modules[-1]
    assert modules.walks == 1


def test_a_copy_with_new_lists_finds_the_new_items() -> None:
    site = demo_site()
    first = site.robots[0]
    assert site.robot(first.name) is first  # the original has built its table
    renamed = site.model_copy(update={"robots": robots(3, "new")})
    assert renamed.robot(first.name) is None
    assert renamed.robot("new2") is renamed.robots[2]
    assert site.robot(first.name) is first  # the original still answers from its own list
    tours = [t.model_copy(update={"name": "Changed"}) for t in site.tours]
    retold = site.model_copy(update={"tours": tours})
    assert retold.tour(tours[0].id) is tours[0]
    assert site.tour(tours[0].id) is site.tours[0]


def test_deep_copies_and_pickles_answer_from_their_own_items() -> None:
    site = demo_site()
    assert site.poi(site.pois[0].id) is site.pois[0]
    for twin in (site.model_copy(deep=True), copy.deepcopy(site), pickle.loads(pickle.dumps(site))):
        assert twin == site
        assert twin.poi(site.pois[0].id) is twin.pois[0]
        assert twin.poi(site.pois[0].id) is not site.pois[0]


def test_an_item_replaced_in_place_is_noticed() -> None:
    site = demo_site()
    old = site.robots[0]
    assert site.robot(old.name) is old
    site.robots[0] = old.model_copy(update={"name": "renamed"})
    assert site.robot(old.name) is None
    assert site.robot("renamed") is site.robots[0]
    site.robots.append(RobotConfig(name="extra", token="token-extra"))
    assert site.robot("extra") is site.robots[-1]


def test_the_lookup_table_does_not_change_equality() -> None:
    site = demo_site()
    twin = Site.model_validate(site.model_dump())
    assert twin._lookups is None  # no lookup yet
    assert site.robot(site.robots[0].name) is not None
    assert site == twin and twin == site


async def test_a_published_draft_edit_is_what_lookups_see() -> None:
    service = SiteService(demo_site(), 1)
    drafts = SiteDrafts(service)
    before = service.site
    assert before.robot("gb_new") is None
    data = copy.deepcopy(drafts.state.data)
    data["robots"].append({"name": "gb_new", "token": "token-gb-new"})
    data["pois"][0]["name"] = "Renamed in the draft"
    state = await drafts.save(data, revision=drafts.state.revision, by="admin")
    await drafts.publish(revision=state.revision, by="admin", secure=lambda site: site)
    after = service.site
    assert after.robot("gb_new") is not None
    assert after.poi(data["pois"][0]["id"]).name == "Renamed in the draft"  # type: ignore[union-attr]
    assert before.robot("gb_new") is None
