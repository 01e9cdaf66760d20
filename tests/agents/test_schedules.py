"""LinearSchedule: the ε schedules of the loop."""

import pytest

from hubsgo_ppl.agents.schedules import LinearSchedule


@pytest.mark.parametrize("progress, expected", [(-0.5, 1.0), (0.0, 1.0), (0.25, 0.55), (0.5, 0.1), (0.9, 0.1)])
def test_decays_linearly_then_holds(progress, expected):
    assert LinearSchedule(1.0, 0.1, 0.5)(progress) == pytest.approx(expected, abs=1e-12)


def test_rises_too_and_a_zero_fraction_is_the_end_value():
    rise = LinearSchedule(0.5, 0.9, 0.3)
    assert [rise(p) for p in (0.0, 0.15, 0.3, 1.0)] == pytest.approx([0.5, 0.7, 0.9, 0.9])
    assert LinearSchedule(1.0, 0.2, 0.0)(0.0) == 0.2
    with pytest.raises(AttributeError):
        rise.start = 0.0                              # frozen: a schedule is a value
