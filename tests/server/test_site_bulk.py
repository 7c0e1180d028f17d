"""A large site validated and dumped in slices gives what pydantic gives in one call, errors
included; the collector pause of site work always ends."""

from __future__ import annotations

import asyncio
import gc
import sys

import pytest

from backend.site.offloop import gc_paused, off_loop
from guidebot.site.bulk import SLICE, dump_site_doc
from guidebot.site.schema import Site
from guidebot.site.synthetic import synthetic_site
from guidebot.site.validate import SiteInvalid, validate_site


@pytest.fixture(scope="module")
def big() -> Site:
    site = synthetic_site(nodes=1500, robots=30, areas=30, pois=20, floors=2)
    assert len(site.nodes) > 2 * SLICE and len(site.edges) > 2 * SLICE
    return site


def test_a_sliced_dump_and_validation_equal_the_whole_document_ones(big: Site) -> None:
    doc = big.model_dump(mode="json")
    sliced = dump_site_doc(big)
    assert sliced == doc and list(sliced) == list(doc)  # same keys in the same order
    assert validate_site(doc) == big


def test_an_error_deep_in_a_long_list_is_reported_at_its_place(big: Site) -> None:
    doc = big.model_dump(mode="json")
    doc["nodes"][SLICE + 7]["x"] = "east"
    doc["edges"][2 * SLICE + 1]["b"] = "nowhere"
    with pytest.raises(SiteInvalid) as refused:
        validate_site(doc)
    where = {issue.loc for issue in refused.value.issues}
    assert f"nodes[{SLICE + 7}].x" in where
    assert any(w.startswith(f"edges[{2 * SLICE + 1}]") for w in where)


async def test_site_work_off_the_loop_restores_the_collector_and_the_switch_interval() -> None:
    interval = sys.getswitchinterval()
    assert gc.isenabled()
    with gc_paused():
        assert not gc.isenabled()
        with pytest.raises(ZeroDivisionError):
            await off_loop(lambda: 1 / 0)
        assert not gc.isenabled()  # the outer block still holds the pause
    assert gc.isenabled() and sys.getswitchinterval() == interval
    assert await asyncio.gather(off_loop(len, "ab"), off_loop(len, "abc")) == [2, 3]
    assert gc.isenabled() and sys.getswitchinterval() == interval
