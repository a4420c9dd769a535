"""terrainvis.core.registry: the rules the four registries share, written once."""

from __future__ import annotations

import pickle

import pytest

import simplifiers
from terrainvis.core.registry import Registry, registry
from terrainvis.experiment.measures import MEASURES
from terrainvis.relocation import RELOCATIONS
from terrainvis.visibility import ENGINES


def test_the_four_registries_are_found_by_kind_with_their_built_in_entries():
    for kind, reg in (("method", simplifiers.METHODS), ("relocation", RELOCATIONS), ("engine", ENGINES),
                      ("measure", MEASURES)):
        assert registry(kind) is reg and reg.kind == kind
        assert reg.builtin <= set(reg) and reg.names() == list(reg)


def test_names_built_ins_and_replacing():
    r = Registry("probe-colour", {"red": 1})
    assert r.add("teal", 2) == 2 and r.names() == ["red", "teal"]
    with pytest.raises(ValueError, match="^a probe-colour named 'teal' is registered already; pass replace=True"):
        r.add("teal", 3)
    assert r.add("teal", 3, replace=True) == 3 and r.names() == ["red", "teal"]  # in place, not moved
    with pytest.raises(ValueError, match="^probe-colour 'red' is built in and cannot be replaced"):
        r.add("red", 4, replace=True)
    with pytest.raises(ValueError, match="^a probe-colour name must be 1-64 characters"):
        r.add("../up", 5)
    with pytest.raises(ValueError, match="^probe-colour 'red' is built in and cannot be removed"):
        r.remove("red")
    with pytest.raises(ValueError, match=r"^no probe-colour named 'blue' is registered; the probe-colours are \['red', "
                                         r"'teal'\]"):
        r.remove("blue")
    assert r.remove("teal") == 3 and r.names() == ["red"]


def test_a_pickled_copy_keeps_its_kind_and_built_ins_and_is_not_the_registry_of_its_kind():
    copy = pickle.loads(pickle.dumps(RELOCATIONS))
    assert isinstance(copy, Registry) and dict(copy) == dict(RELOCATIONS)
    assert copy.kind == "relocation" and copy.builtin == RELOCATIONS.builtin
    assert registry("relocation") is RELOCATIONS and copy is not RELOCATIONS
