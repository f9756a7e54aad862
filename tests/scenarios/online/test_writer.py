"""The writer's limits: rate limit around the reference, then bounds; non-finite refused."""

import math

from scenarios.online import Limit, limit_move

FEED = Limit("feed_tph", 20.0, 45.0, rate_max_per_h=20.0)


def test_a_move_is_clipped_to_the_rate_limit_then_to_the_bounds():
    assert limit_move(30.0, 29.5, 0.05, FEED) == (30.0, [])
    value, notes = limit_move(40.0, 30.0, 0.05, FEED)  # 1 t/h a sample allowed
    assert value == 31.0 and "rate limit" in notes[0]
    value, notes = limit_move(19.0, 20.5, 0.05, FEED)
    assert value == 20.0 and "rate limit" in notes[0] and "bound [20, 45]" in notes[1]


def test_no_reference_means_bounds_only_and_non_finite_is_refused():
    assert limit_move(50.0, None, 0.05, FEED)[0] == 45.0
    value, notes = limit_move(math.nan, 30.0, 0.05, FEED)
    assert value == 30.0 and "refused" in notes[0]
    assert limit_move(math.inf, None, 0.05, FEED)[0] is None


def test_an_infinite_rate_limit_is_no_limit():
    assert limit_move(44.0, 20.0, 0.05, Limit("f", 20.0, 45.0))[0] == 44.0


def test_a_setpoint_left_outside_the_bounds_comes_back_at_once_and_says_so():
    """After a manual period at 50 t/h (bounds 20-45, 1 t/h a sample) the first write is 45: the
    bounds come first, a move of -5 against a rate limit of 1, which was said nowhere."""
    value, notes = limit_move(40.0, 50.0, 0.05, FEED)
    assert value == 45.0 and "exceeds the rate limit" in notes[-1] and "-5" in notes[-1]
    assert len(limit_move(44.0, 45.0, 0.05, FEED)[1]) == 0
