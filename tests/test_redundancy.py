"""2-out-of-2 wayside comparison and 2-out-of-3 receiver voting."""
import pytest

from fmus.signalling.fire_dqpsk import COMMANDS
from fmus.signalling.redundancy import STATUS_FAILED, STATUS_OK, STATUS_PARTIAL, vote_2oo3, wayside_2oo2


def rank(command):
    c = COMMANDS[command]
    return (c.permitted_kmh[1], c.free_blocks)        # lower passenger speed = more restrictive


def test_wayside_generators_agree_or_send_the_more_restrictive():
    assert wayside_2oo2(13, 13, True, True, rank) == (13, STATUS_OK)
    assert wayside_2oo2(13, 5, True, True, rank) == (5, STATUS_OK)
    assert wayside_2oo2(2, 16, True, True, rank) == (2, STATUS_OK)
    assert wayside_2oo2(13, None, True, True, rank) == (None, STATUS_OK)


def test_wayside_falls_back_to_the_reserve_then_to_no_output():
    assert wayside_2oo2(13, 13, False, True, rank) == (13, STATUS_PARTIAL)
    assert wayside_2oo2(13, 11, True, False, rank) == (13, STATUS_PARTIAL)
    assert wayside_2oo2(13, 13, False, False, rank) == (None, STATUS_FAILED)


@pytest.mark.parametrize("channels, healthy, expected", [
    ((7, 7, 7), (True, True, True), 7),
    ((7, 7, 16), (True, True, True), 7),              # one channel wrong: outvoted
    ((16, 7, 16), (True, True, False), None),         # the faulty one cannot make a majority
    ((7, 16, 2), (True, True, True), None),           # all disagree: no output, restrictive
    ((7, None, 7), (True, True, True), 7),            # one channel silent
    ((7, None, None), (True, True, True), None),      # a single channel never suffices
    ((7, 7, 7), (False, False, True), None),
])
def test_receiver_votes_two_out_of_three(channels, healthy, expected):
    assert vote_2oo3(channels, healthy) == expected
