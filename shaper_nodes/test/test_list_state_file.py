"""The learner's state file at start-up: every corrupt file is reported and ignored, never fatal.

Each class of corrupt file (nested 100k deep, too deep, truncated, not UTF-8, wrong types,
non-finite values, entries missing or unknown, saved for another set-up) is loaded the way the
learner node loads it (:func:`load_state` with the LIST mode's builder): nothing is loaded, the
problem is named, the file is moved aside; in a folder where it cannot be moved aside it stays,
is reported as such, and the next start refuses it the same way without raising either. The MRILC
state's own classes are in test_mrilc.py.
"""

from __future__ import annotations

import json
import pathlib

import pytest

from shaper_nodes.core.learning.list import ListConfig, ListLearner, ListParams, learner_from_state
from shaper_nodes.core.learning.state_file import (
    MAX_DEPTH,
    load_state,
    nesting_depth,
    read_state,
    set_aside,
    write_state,
)

VERSION = 1


def good_document() -> dict:
    learner = ListLearner(ListConfig(), ListParams(0.6, 0.1))
    return {"version": VERSION, "structure": "zv2", "saved_at": 1.0, "learner": learner.to_dict()}


def edit(fn) -> str:
    doc = good_document()
    fn(doc)
    return json.dumps(doc)


def deep(levels: int) -> str:
    return "[" * levels + "]" * levels


#: corrupt state files: (name, text or bytes, words the problem must contain)
CORRUPT = [
    ("nested 100k deep", deep(100_000), "nested too deeply"),
    ("nested 100k deep inside the learner",
     '{"version": 1, "structure": "zv2", "learner": ' + deep(100_000) + "}", "nested too deeply"),
    ("nested deeper than allowed", deep(MAX_DEPTH + 1), "deeper than"),
    ("truncated JSON", '{"version": 1, "structure": "zv2", "learner": {"params": [0.5', "not valid JSON"),
    ("empty", "", "not valid JSON"),
    ("not UTF-8", b"\xff\xfe\x00{", "cannot read"),
    ("an integer too long to convert", "1" * 5000, "not valid JSON"),
    ("not a document", "[1, 2, 3]", "not a version-1 state file"),
    ("another version", edit(lambda d: d.update(version=2)), "not a version-1 state file"),
    ("another structure", edit(lambda d: d.update(structure="zvd3")), "saved for structure 'zvd3'"),
    ("an unknown entry", edit(lambda d: d.update(extra=1)), "unknown ['extra']"),
    ("no learner", edit(lambda d: d.pop("learner")), "missing ['learner']"),
    ("saved_at a text", edit(lambda d: d.update(saved_at="yesterday")), "saved_at"),
    ("the learner a list", edit(lambda d: d.update(learner=[])), "must be a dictionary"),
    ("iteration a text", edit(lambda d: d["learner"].update(iteration="3")), "iteration must be an integer"),
    ("a NaN parameter", edit(lambda d: d["learner"]["params"].update(t2=float("nan"))), "finite"),
    ("an infinite parameter", edit(lambda d: d["learner"]["params"].update(a1=float("inf"))), "finite"),
    ("history of lists", edit(lambda d: d["learner"].update(history=[[]])), "history must be a list of dict"),
]


def write(path: pathlib.Path, content: str | bytes) -> None:
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content, encoding="utf-8")


def load(path: pathlib.Path):
    return load_state(path, VERSION, learner_from_state, "learner state", {"structure": "zv2"})


@pytest.fixture
def unmovable(tmp_path):
    """A folder where a state file cannot be moved aside: read-only (for a user other than root,
    whom permissions do not stop) and with ``state.json.corrupt`` a folder that is not empty, which
    stops even root's rename."""
    folder = tmp_path / "read_only"
    folder.mkdir()
    (folder / "state.json.corrupt").mkdir()
    (folder / "state.json.corrupt" / "keep").write_text("")
    yield folder
    folder.chmod(0o755)


def make_read_only(folder: pathlib.Path) -> None:
    folder.chmod(0o555)


def test_a_good_document_round_trips():
    doc = good_document()
    learner = learner_from_state(json.loads(json.dumps(doc)))
    assert learner.to_dict() == doc["learner"]


def test_a_saved_state_loads(tmp_path):
    path = tmp_path / "state.json"
    write_state(path, good_document())
    loaded = load(path)
    assert loaded.problem == "" and loaded.state is not None and loaded.state.params == ListParams(0.6, 0.1)
    assert load(tmp_path / "none.json").state is None and load(tmp_path / "none.json").problem == ""
    assert load_state(None, VERSION, learner_from_state).state is None


@pytest.mark.parametrize("name, content, words", CORRUPT, ids=[c[0] for c in CORRUPT])
def test_a_corrupt_file_is_reported_moved_aside_and_ignored(tmp_path, name, content, words):
    path = tmp_path / "state.json"
    write(path, content)
    loaded = load(path)  # never raises
    assert loaded.state is None
    assert words in loaded.problem and "starting afresh" in loaded.problem, loaded.problem
    assert loaded.aside == tmp_path / "state.json.corrupt" and loaded.aside.exists() and not path.exists()
    again = load(path)  # the next start: nothing there, a fresh learner, nothing to report
    assert again.state is None and again.problem == ""


@pytest.mark.parametrize("name, content, words", CORRUPT, ids=[c[0] for c in CORRUPT])
def test_a_corrupt_file_that_cannot_be_moved_aside_is_reported_and_ignored_at_every_start(unmovable, name, content,
                                                                                           words):
    path = unmovable / "state.json"
    write(path, content)
    make_read_only(unmovable)
    for _ in range(2):  # this start and the next: the same refusal, never an exception
        loaded = load(path)
        assert loaded.state is None and loaded.aside is None
        assert words in loaded.problem and "could not be moved aside" in loaded.problem, loaded.problem
        assert "refused again at the next start" in loaded.problem
        assert path.exists()


def test_an_unreadable_file_is_reported(tmp_path, monkeypatch):
    path = tmp_path / "state.json"
    write_state(path, good_document())

    def denied(self, *args, **kwargs):
        raise PermissionError(13, "Permission denied", str(self))

    monkeypatch.setattr(pathlib.Path, "read_text", denied)
    loaded = load(path)
    assert loaded.state is None and "cannot read" in loaded.problem and "Permission denied" in loaded.problem


def test_a_builder_that_fails_in_any_way_is_reported(tmp_path):
    path = tmp_path / "state.json"
    write_state(path, good_document())

    def broken(doc):
        return doc["learner"]["history"][5]  # IndexError: not one of the learner's own errors

    loaded = load_state(path, VERSION, broken)
    assert loaded.state is None and "IndexError" in loaded.problem and loaded.aside is not None


def test_a_file_too_long_is_refused_before_it_is_read(tmp_path, monkeypatch):
    from shaper_nodes.core.learning import state_file

    path = tmp_path / "state.json"
    write_state(path, good_document())
    monkeypatch.setattr(state_file, "MAX_BYTES", 10)
    with pytest.raises(state_file.StateFileError, match="more than the 10"):
        read_state(path, VERSION)


def test_nesting_depth_counts_without_recursion():
    assert nesting_depth(1) == 0 and nesting_depth([]) == 1 and nesting_depth({"a": [1, {"b": []}]}) == 4
    doc: list = []
    for _ in range(50_000):  # deeper than Python's recursion limit
        doc = [doc]
    assert nesting_depth(doc) == 50_001
    assert nesting_depth(good_document()) <= MAX_DEPTH


def test_set_aside_raises_where_the_file_cannot_move(unmovable):
    path = unmovable / "state.json"
    path.write_text("{}")
    with pytest.raises(OSError):
        set_aside(path)
