"""One record type for every fix an estimator attempted: its fields, its verdict, its JSON form."""

from __future__ import annotations

import json
import types

import numpy as np

from tangraph.fix_records import FixRecord, FixStatus


def test_a_record_holds_the_fix_and_what_became_of_it():
    covariance = np.array([[4.0, 1.0], [1.0, 9.0]])
    fix = types.SimpleNamespace(position=np.array([10.0, -4.0]), covariance=covariance)
    record = FixRecord.of(19, fix, FixStatus.ACCEPTED, 2.5, 30.0)
    assert record.accepted and record.reason == "accepted" and record.index == 19
    np.testing.assert_array_equal(record.position, fix.position)
    np.testing.assert_array_equal(record.covariance, fix.covariance)
    held = FixRecord.of(24, fix, FixStatus.HELD, 9.0, 30.0, "surprising")
    assert not held.accepted and held.reason == "held: surprising"
    failed = FixRecord.of(29, None, FixStatus.MATCH_FAILED, np.nan, 30.0, "no soundings")
    assert np.isnan(failed.position).all() and np.isnan(failed.covariance).all()
    assert json.loads(json.dumps(held.as_dict()))["status"] == "held"


def test_only_the_gate_and_a_best_match_on_the_edge_say_the_prediction_is_wrong():
    assert {s for s in FixStatus if s.says_lost} == {FixStatus.GATE, FixStatus.OUTSIDE_SEARCH}
