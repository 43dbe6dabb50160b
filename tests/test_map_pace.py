"""The time budget of ``droidw map``: a deadline, and the pacing that spreads steps over the keyframes."""

from __future__ import annotations

import time

from droidw_cli.gaussians.static_map import Deadline, Pace


def test_a_spent_deadline_is_over_and_the_pace_behind():
    spent = Deadline(time.perf_counter() - 10.0, 5.0)
    assert spent.over()
    assert Pace(spent, 1.0).behind(1.0)


def test_a_fresh_budget_allows_each_share_in_turn():
    pace = Pace(Deadline(time.perf_counter(), 1000.0), 0.5)
    assert not pace.behind(0.01) and not pace.behind(1.0)
    pace.t0 -= 400.0  # 400 s into 1000 s, half of which is this loop's: 40 % of the loop may have run
    assert pace.behind(0.5) and not pace.behind(0.9)
