import math

import pytest

from softcath_ros.core.answer_load import AnswerLoad


def test_keeping_up():
    load = AnswerLoad(start_s=0.0)
    for _ in range(1000):            # 1 kHz for 1 s, 50 us per answer
        load.record(50e-6)
    r = load.report(1.0)
    assert r.commands == 1000 and r.command_rate_hz == pytest.approx(1000.0)
    assert r.mean_answer_s == pytest.approx(50e-6) and r.max_rate_hz == pytest.approx(2e4)
    assert r.busy_fraction == pytest.approx(0.05) and not r.behind


def test_falling_behind_and_new_window():
    load = AnswerLoad(start_s=10.0)
    for _ in range(19):              # a slow rung answering back to back: 19 x 50 ms in 1 s
        load.record(0.05)
    r = load.report(11.0)
    assert r.behind and r.busy_fraction == pytest.approx(0.95) and r.max_rate_hz == pytest.approx(20.0)
    empty = load.report(12.0)        # the next window starts afresh
    assert empty.commands == 0 and not empty.behind and math.isinf(empty.max_rate_hz)


def test_threshold_is_checked():
    with pytest.raises(ValueError):
        AnswerLoad(0.0, behind_at=0.0)
