"""Diagnostics as data (issue 26): a message with a code, a severity and values, stored as
records and read back by code."""

import copy
import json
import pickle

import numpy as np
import pytest

from idtool._diagnostic import (
    BANNER_CODES,
    CODES,
    Diagnostic,
    from_records,
    has_code,
    records,
    reworded,
    with_code,
)


def test_a_diagnostic_is_its_message_and_keeps_its_code_through_files_and_copies():
    d = Diagnostic(
        "correlation", "a and b are correlated", parameters=("a", "b"), r=np.float64(0.97)
    )
    assert d == "a and b are correlated" and d.startswith("a and")  # still a sentence
    assert d.code == "correlation" and d.severity == "warning"
    assert d.values == {"parameters": ["a", "b"], "r": 0.97}  # plain, JSON-ready
    for again in (copy.deepcopy(d), pickle.loads(pickle.dumps(d))):
        assert again == d and again.code == d.code and again.values == d.values
    doc = json.loads(json.dumps(records([d, "a plain sentence"])))
    back = from_records(doc)
    assert [b.code for b in back] == ["correlation", "fit"] and back == [d, "a plain sentence"]
    assert json.dumps([d]) == '["a and b are correlated"]'  # lists of warnings stay sentences


def test_codes_are_declared_and_read_by_code():
    with pytest.raises(ValueError, match="not declared"):
        Diagnostic("misfitt", "a typo must not hide a banner")
    with pytest.raises(ValueError, match="severity"):
        Diagnostic("fit", "x", severity="fatal")
    assert set(CODES) >= BANNER_CODES
    items = [Diagnostic("drift_on", "fading"), "plain", Diagnostic("bound", "at bound")]
    assert with_code(items, "drift_on", "drift_off") == ["fading"]
    assert has_code(items[2], "bound") and not has_code("plain", "bound")
    moved = reworded(items[0], "fading, said otherwise", size=0.1)
    assert moved.code == "drift_on" and moved.values == {"size": 0.1}
    assert reworded("plain", "still plain") == "still plain"
