"""components(): the connected components the package's groupings rest on."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from intersection_estimator.components import components


def _reach(items, pairs):
    """Components by breadth-first search (the reference)."""
    nbr = {k: set() for k in items}
    for a, b in pairs:
        nbr[a].add(b)
        nbr[b].add(a)
    seen, out = set(), []
    for k in items:
        if k in seen:
            continue
        todo, comp = [k], set()
        while todo:
            x = todo.pop()
            if x not in comp:
                comp.add(x)
                todo.extend(nbr[x] - comp)
        seen |= comp
        out.append(comp)
    return out


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(0, 30), min_size=1, max_size=30, unique=True).flatmap(
    lambda items: st.tuples(st.just(items), st.lists(st.tuples(st.sampled_from(items), st.sampled_from(items)),
                                                     max_size=40))))
def test_components_equal_breadth_first_search(case):
    items, pairs = case
    got = components(items, pairs)
    assert sorted(map(frozenset, got), key=min) == sorted(map(frozenset, _reach(items, pairs)), key=min)
    assert [min(g) for g in got] == sorted(min(g) for g in got)            # ordered by smallest
    for g in got:                                                           # input order kept inside
        assert g == [k for k in items if k in set(g)]


def test_no_pairs_and_string_keys():
    assert components(['b', 'a', 'b'], []) == [['a'], ['b']]
    assert components(['n3', 'n1', 'n2'], [('n3', 'n2')]) == [['n1'], ['n3', 'n2']]
