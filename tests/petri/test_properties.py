"""Properties over many generated nets: writing and reading back loses nothing, the reader
never fails with anything but a reported problem."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from petri_nets.builder import NetBuilder, message, publish
from petri_nets.pnml import read_pnml, write_pnml

ids = st.from_regex(r"[a-z][a-z0-9_]{0,8}", fullmatch=True)
# names and descriptions are read stripped (other tools indent them), so generate them stripped
texts = st.text(
    st.characters(codec="utf-8", exclude_categories=("Cs", "Cc", "Zs", "Zl", "Zp")), max_size=12
)


@st.composite
def nets(draw: st.DrawFn) -> NetBuilder:
    names = draw(st.lists(ids, min_size=2, max_size=8, unique=True))
    places, transitions = names[: len(names) // 2 + 1], names[len(names) // 2 + 1 :]
    b = NetBuilder("n", draw(texts))
    for place in places:
        action = publish("say", {"text": draw(texts)}) if draw(st.booleans()) else None
        b.place(
            f"p_{place}",
            initial=draw(st.integers(0, 3)),
            action=action,
            final=draw(st.booleans()),
            name=draw(texts) or None,
        )
    for transition in transitions:
        ins = draw(st.dictionaries(st.sampled_from(places), st.integers(1, 4), max_size=3))
        outs = draw(st.dictionaries(st.sampled_from(places), st.integers(1, 4), max_size=3))
        condition = message("ping", who=draw(texts)) if draw(st.booleans()) else None
        b.transition(
            f"t_{transition}",
            {f"p_{k}": v for k, v in ins.items()},
            {f"p_{k}": v for k, v in outs.items()},
            condition,
            priority=draw(st.integers(-2, 2)),
        )
    return b


def summary(data: bytes) -> object:
    doc, problems = read_pnml(data)
    assert problems == [] and doc is not None
    return (
        doc.description,
        [
            (p.id, p.name, p.initial, p.final, p.action.body if p.action else None)
            for p in doc.places
        ],
        [
            (
                t.id,
                t.priority,
                [(m.field, m.value) for m in t.condition.matches] if t.condition else None,
            )
            for t in doc.transitions
        ],
        [(a.source, a.target, a.weight) for a in doc.arcs],
    )


@settings(max_examples=25, deadline=None)
@given(nets())
def test_write_read_write_is_lossless(builder: NetBuilder) -> None:
    first = write_pnml(builder.build())
    doc, _ = read_pnml(first)
    assert doc is not None
    assert write_pnml(doc) == first
    assert summary(first) == summary(write_pnml(doc))


@settings(max_examples=50, deadline=None)
@given(st.binary(max_size=300) | texts.map(lambda t: f"<pnml><net id='x'>{t}</net></pnml>"))
def test_any_input_gives_problems_not_crashes(data: bytes | str) -> None:
    doc, problems = read_pnml(data, "fuzz.pnml")
    assert doc is not None or problems
    assert all(p.file == "fuzz.pnml" for p in problems)
