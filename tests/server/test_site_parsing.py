"""The site's slow-but-yielding parsers and writers give what the fast one-call ones give (data
and errors), and large objects are freed a piece at a time only when nobody else holds them."""

from __future__ import annotations

import asyncio
import json
from collections.abc import Callable
from typing import Any

import orjson
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from yaml.composer import Composer

from backend.db import DbStore, make_engine, make_sessionmaker, migrate
from backend.site.yaml_import import read_site_yaml
from guidebot.site import jsonio
from guidebot.site.dispose import dispose
from guidebot.site.schema import Site
from guidebot.site.synthetic import synthetic_site
from guidebot.site.validate import SiteInvalid
from guidebot.site.yamlio import LOADER, dump_site, load_site_text, load_yaml, yaml_as_json
from tests.server.workers import killing_new_workers


@pytest.fixture(scope="module")
def big() -> Site:
    return synthetic_site(nodes=3000, robots=20, areas=20, pois=20, floors=2)


def _c_load(text: str) -> object:
    return yaml.load(text, Loader=yaml.CSafeLoader)


def test_the_yaml_tree_is_composed_in_python_over_libyaml_events() -> None:
    assert LOADER.get_single_node is Composer.get_single_node
    assert "CParser" in [c.__name__ for c in LOADER.__mro__]


def test_a_large_yaml_site_loads_as_with_libyaml_alone(big: Site) -> None:
    text = dump_site(big)
    assert load_yaml(text) == _c_load(text)
    assert load_site_text(text) == big


@pytest.mark.parametrize(
    "text",
    [
        "a: [1, 2\nb: 3\n",
        "a: 1\n  b: 2\n",
        "a: *nowhere\n",
        "a: &x 1\nb: &x 2\n",
        "a: 1\n---\nb: 2\n",
        "a: !!python/object:os.system x\n",
        "a: &A {x: 1}\nb: {<<: *A, y: 2}\nc: 2001-12-14\nd: .inf\ne: 0x1f\n",
        "",
    ],
)
def test_yaml_data_and_errors_are_libyamls(text: str) -> None:
    try:
        expected: object = _c_load(text)
    except yaml.YAMLError as exc:
        with pytest.raises(type(exc)) as got:
            load_yaml(text)
        assert str(got.value) == str(exc)
        assert got.value.problem_mark.line == exc.problem_mark.line  # type: ignore[attr-defined]
    else:
        assert load_yaml(text) == expected


def test_a_refused_large_yaml_site_still_gives_lines(big: Site) -> None:
    head, sep, nodes = dump_site(big).partition("\nnodes:\n")
    text = head + sep + nodes.replace("  x: ", "  x: east  # ", 1)
    with pytest.raises(SiteInvalid) as refused:
        load_site_text(text)
    [issue] = refused.value.issues
    assert issue.line is not None and "east" in text.splitlines()[issue.line - 1]


def test_a_large_json_document_parses_and_writes_as_with_orjson(big: Site) -> None:
    doc = big.model_dump(mode="json")
    raw = orjson.dumps(doc)
    assert len(raw) > jsonio.LARGE
    assert jsonio.loads(raw) == orjson.loads(raw) == doc
    assert jsonio.dumps_bytes(doc) == raw
    assert jsonio.dumps(doc) == raw.decode()


def test_a_large_document_is_written_in_short_native_calls(
    big: Site, monkeypatch: pytest.MonkeyPatch
) -> None:
    """No single orjson call writes the whole site (one call holds the GIL 6-25 ms)."""
    doc = {"version": 3, "site": big.model_dump(mode="json")}
    written: list[int] = []
    dumps = orjson.dumps

    def counting(value: object) -> bytes:
        data = dumps(value)
        written.append(len(data))
        return data

    monkeypatch.setattr(jsonio.orjson, "dumps", counting)
    total = len(jsonio.dumps_bytes(doc))
    assert total > jsonio.LARGE
    assert max(written) < total / 10


def same_as_orjson(ours: Callable[[Any], Any], theirs: Callable[[Any], Any], arg: Any) -> Any:
    """``ours(arg)`` gives what ``theirs(arg)`` gives (returned), or raises its error with the
    same message (None)."""
    try:
        expected = theirs(arg)
    except (orjson.JSONDecodeError, orjson.JSONEncodeError) as exc:
        with pytest.raises(type(exc)) as raised:
            ours(arg)
        assert str(raised.value) == str(exc)
        return None
    got = ours(arg)
    assert got == expected
    return got


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
    lambda inner: (
        st.lists(inner, max_size=jsonio.SLICE + 30)
        | st.dictionaries(st.text(max_size=5), inner, max_size=4)
    ),
    max_leaves=600,
)


@settings(max_examples=60, deadline=None)
@given(json_values)
def test_written_in_pieces_is_byte_for_byte_what_orjson_writes(value: object) -> None:
    """Long lists at any depth, NaN (written as null), escapes in keys: the same bytes."""
    same_as_orjson(jsonio.dumps_bytes, orjson.dumps, value)


@pytest.mark.parametrize("number", [2**64, -(2**63) - 1, 10**30])
def test_a_large_document_with_an_integer_beyond_64_bits_is_refused_as_orjson_does(
    big: Site, number: int
) -> None:
    """Written, it would come back from the database as a float: refused instead (the
    server answers 422, docs/server.md "Status codes")."""
    doc = big.model_dump(mode="json")
    doc["robots"][0]["params"] = {"serial": number}
    with pytest.raises(orjson.JSONEncodeError) as expected:
        orjson.dumps(doc)
    with pytest.raises(orjson.JSONEncodeError) as got:
        jsonio.dumps(doc)
    assert str(got.value) == str(expected.value)
    doc["robots"][0]["params"] = {"serial": 2**64 - 1, "low": -(2**63), "flag": True}
    assert orjson.loads(jsonio.dumps(doc)) == doc


@pytest.mark.parametrize(
    "tail",
    [
        b'"x": NaN}',  # not JSON
        b'"x": 1e400}',  # overflows a double
        b'"x": "\\ud800"}',  # a lone surrogate
        b'"x": [1, 2,]}',  # broken
        b'"x": "\xff"}',  # not UTF-8
        b'"x": 18446744073709551616, "y": -9223372036854775809}',  # beyond 64 bits: a float
    ],
)
def test_large_json_edge_cases_follow_orjson(tail: bytes) -> None:
    raw = b'{"pad": "' + b"p" * (jsonio.LARGE + 10) + b'", ' + tail
    got = same_as_orjson(jsonio.loads, orjson.loads, raw)
    if got is not None:
        expected = orjson.loads(raw)
        assert [type(v) for v in got.values()] == [type(v) for v in expected.values()]


def test_small_json_documents_take_the_fast_path() -> None:
    assert jsonio.loads(b'{"a": [1, 2.5, "\\u00e9"]}') == {"a": [1, 2.5, "é"]}
    assert jsonio.dumps({"a": [1, 2.5]}) == '{"a":[1,2.5]}'
    with pytest.raises(orjson.JSONDecodeError):
        jsonio.loads(b'{"a": NaN}')


def test_dispose_takes_apart_only_what_nobody_else_holds() -> None:
    shared = {"kept": list(range(100))}
    box = [{"nodes": [{"id": str(i), "xy": [i, i]} for i in range(500)], "shared": shared}]
    assert dispose(box) > 500
    assert box == [] and shared == {"kept": list(range(100))}  # untouched: still referenced
    held = [[1, 2, 3] * 10]
    alias = held[0]
    assert dispose(held) == 0 and alias == [1, 2, 3] * 10


async def test_a_large_site_stored_is_read_back_the_same(db_url: str, big: Site) -> None:
    engine = make_engine(db_url)
    try:
        await migrate(engine)
        store = DbStore(make_sessionmaker(engine))
        doc = big.model_dump(mode="json")
        assert len(json.dumps(doc)) > jsonio.LARGE
        assert await store.save_site(doc, by="admin") == 1
        assert await store.save_site(doc) == 2
        assert await store.load_site() == (2, doc)
        assert await store.site_version(1) == doc
    finally:
        await engine.dispose()


def test_a_large_yaml_site_read_as_json_by_a_worker_loads_the_same(
    big: Site, caplog: pytest.LogCaptureFixture
) -> None:
    text = dump_site(big)
    parsed = yaml_as_json(text)
    assert parsed is not None and orjson.loads(parsed) == _c_load(text)
    assert load_site_text(text, parsed) == big
    # in a real worker process, as the import endpoints read a file above jsonio.LARGE
    assert len(text) > jsonio.LARGE
    assert asyncio.run(read_site_yaml(text, workers=1)) == big
    assert "worker process failed" not in caplog.text


@pytest.mark.parametrize(
    "text",
    [
        "a: [1, 2\nb: 3\n",  # broken: load_site_text words the error, with its line
        "- a\n- b\n",  # not a mapping
        "a: &x [1]\n" + "".join(f"b{i}: *x\n" for i in range(101)),  # too many aliases
        "name: x\nopened: 2001-12-14\n",  # a date: JSON would make it a string
        "name: x\nscale: .nan\n",  # NaN: JSON has none
        "name: x\n1: one\n",  # a key that is not a string
    ],
)
def test_yaml_that_json_would_not_carry_exactly_is_left_to_load_site_text(text: str) -> None:
    assert yaml_as_json(text) is None


def test_a_refused_large_yaml_site_read_by_a_worker_gives_the_same_lines(big: Site) -> None:
    head, sep, nodes = dump_site(big).partition("\nnodes:\n")
    text = head + sep + nodes.replace("  x: ", "  x: east  # ", 1)
    with pytest.raises(SiteInvalid) as in_thread:
        load_site_text(text)
    with pytest.raises(SiteInvalid) as with_worker:
        asyncio.run(read_site_yaml(text, workers=1))
    assert with_worker.value.issues == in_thread.value.issues


def test_a_killed_yaml_worker_falls_back_to_the_thread_and_loads_the_same(
    big: Site, caplog: pytest.LogCaptureFixture
) -> None:
    text = dump_site(big)
    assert asyncio.run(killing_new_workers(read_site_yaml(text, workers=1))) == big
    assert "worker process failed" in caplog.text
