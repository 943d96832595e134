"""The per-move store: identities from poses or names, entries checked one by one, atomic saves."""

from __future__ import annotations

import json

import numpy as np
import pytest

from shaper_nodes.core.learning.list import ListConfig, ListLearner, ListParams
from shaper_nodes.core.learning.moves import MoveError, MoveStore, move_key, store_from_doc
from shaper_nodes.core.learning.speed import SpeedLearner

A = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
B = [1.2, -1.57, 1.57, -1.57, -1.57, 0.0]


def test_a_move_is_identified_by_its_poses_to_a_milliradian_or_by_its_name():
    assert move_key(A, B) == move_key(np.array(A) + 1e-5, B)  # the controller's end-point error
    assert move_key(A, B) != move_key(B, A)  # the way back is another move
    assert move_key(A, B) != move_key(A, np.array(B) + 2e-3)
    assert move_key(A, B, "pick") == "pick"
    with pytest.raises(MoveError, match="joints"):
        move_key(A, B[:5])
    with pytest.raises(MoveError, match="finite"):
        move_key([float("nan")] * 6, B)
    with pytest.raises(MoveError, match="name"):
        move_key(A, B, " ")


def _store() -> MoveStore:
    store = MoveStore()
    e, new = store.entry(A, B)
    assert new
    learner = ListLearner(ListConfig(), ListParams(0.52, 0.05))
    e.list_state = learner.to_dict()
    e.correction = ([0.5, 0.5], [0.0, 0.025])
    e.base = {"residual_rms": 0.01, "move_settle_s": 1.1}
    sp = SpeedLearner()
    sp.update(True)
    e.speed_state = sp.to_dict()
    e.cycles = 3
    e2, _ = store.entry(B, A, name="back", origin="design")
    e2.cycles = 1
    return store


def test_the_store_saves_atomically_and_loads_back_every_entry(tmp_path):
    store = _store()
    e, new = store.entry(np.array(A) + 1e-5, B)
    assert not new and e.cycles == 3
    path = tmp_path / "moves.json"
    store.save(path, saved_at=12.0)
    assert not (tmp_path / "moves.json.tmp").exists()
    back, problems = store_from_doc(json.loads(path.read_text()))
    assert problems == {}
    assert back.to_doc(12.0) == store.to_doc(12.0)
    assert back.get("back").origin == "design"
    assert back.get(move_key(A, B)).learner().params == ListParams(0.52, 0.05)
    assert back.get(move_key(A, B)).speed().factor == pytest.approx(1.1)


def test_a_broken_entry_is_left_out_with_its_reason_and_the_others_load():
    doc = _store().to_doc()
    key = move_key(A, B)
    doc["moves"][key]["speed"]["factor"] = -1.0
    doc["moves"]["back"]["goal"] = [0.0] * 6  # the key (a name) still matches
    back, problems = store_from_doc(doc)
    assert list(problems) == [key] and "factor" in problems[key]
    assert "back" in back and key not in back


@pytest.mark.parametrize(("mutate", "match"), [
    (lambda e: e.update(key="pose-0000000000000000"), "neither"),
    (lambda e: e.update(origin="guess"), "origin"),
    (lambda e: e.update(cycles=-1), "cycles"),
    (lambda e: e.update(correction={"amplitudes": [0.6, 0.6], "times": [0.0, 0.02]}), "sum to 1"),
    (lambda e: e.update(base={"residual_rms": float("nan"), "move_settle_s": 1.0}), "residual_rms"),
    (lambda e: e.update(list={"format": "x"}), "LIST|list|state"),
    (lambda e: e.pop("speed"), "missing"),
])
def test_each_entry_is_checked_and_the_problem_named(mutate, match):
    doc = _store().to_doc()
    key = move_key(A, B)
    entry = dict(doc["moves"][key])
    mutate(entry)
    doc["moves"][key] = entry
    _, problems = store_from_doc(doc)
    assert key in problems
    assert pytest.importorskip("re").search(match, problems[key])


def test_a_document_of_another_version_is_refused_whole():
    doc = _store().to_doc()
    with pytest.raises(MoveError, match="version"):
        store_from_doc({**doc, "version": 2})
    with pytest.raises(MoveError, match="unknown"):
        store_from_doc({**doc, "extra": 1})


def test_relearn_resets_every_move_but_keeps_its_identity():
    store = _store()
    keys = store.relearn("identified")
    assert sorted(keys) == sorted([move_key(A, B), "back"])
    e = store.get(move_key(A, B))
    assert (e.origin, e.cycles, e.list_state, e.correction, e.base) == ("identified", 0, None, None, None)
    assert e.speed().factor == 1.0
