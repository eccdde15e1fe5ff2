"""``jaxgfx.testing.problems.settle_step``: the settling criterion of ``benchmarks.inverse`` and
``experiments.fit_settle`` (the mean of the last ``window`` iterates within ``rel`` of the truth
from that iterate to the last one), on sequences whose answer is worked out by hand."""

from jaxgfx.testing import problems


def test_first_window_inside_the_band_and_staying_there():
    a = [0.5, 0.3, 0.2, 0.17, 0.16, 0.152, 0.15, 0.15, 0.151, 0.149, 0.15, 0.15]
    # windows of 5 ending at index 7: mean 0.1564 (outside 0.147..0.153); at 8: 0.1526 (inside)
    assert problems.settle_step(a, 0.15) == 8
    # window 1: the first iterate within 2 % that stays is index 5 (0.152)
    assert problems.settle_step(a, 0.15, window=1) == 5


def test_leaving_the_band_at_the_end_is_not_settled_and_a_dip_restarts_it():
    a = [0.15] * 10 + [0.2]
    assert problems.settle_step(a, 0.15, window=1) is None
    b = [0.15] * 5 + [0.2] + [0.15] * 5
    # the mean of 5 containing 0.2 is 0.16 (outside); the first all-0.15 window ends at index 10
    assert problems.settle_step(b, 0.15) == 10
    assert problems.settle_step([0.15] * 3, 0.15) is None  # shorter than one window
