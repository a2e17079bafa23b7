"""Tests of the joint-angle figure's helpers (regrasp_pin.plotting.joints)."""

from __future__ import annotations

from regrasp_pin.plotting.joints import regrasp_runs


def test_back_to_back_regrasps_share_one_shaded_run_and_label():
    # the second lands as the third lifts off (1e-9 s apart), the first stands alone
    spans = [(1.01, 1.26), (0.76, 1.01), (3.0, 3.25), (1.26 + 1e-9, 1.5)]
    assert regrasp_runs(spans) == [(0.76, 1.5, 3), (3.0, 3.25, 1)]


def test_regrasps_apart_stay_apart():
    assert regrasp_runs([(0.0, 0.25), (0.2501, 0.5)]) == [(0.0, 0.25, 1), (0.2501, 0.5, 1)]
    assert regrasp_runs([]) == []
