import math

import numpy as np
import pytest

from softcath_ros.core.pressure_command import check_pressure_command


def test_accepts_valid():
    c = check_pressure_command([100.0, 0.0], 2, 5e4)
    assert c.status == "ok" and c.pressures.tolist() == [100.0, 0.0]


@pytest.mark.parametrize("values,fragment", [
    ([math.nan], "non-finite"), ([math.inf], "non-finite"), ([1.0, 2.0], "wrong number"), ([], "wrong number")])
def test_always_rejected(values, fragment):
    for policy in ("reject", "clamp"):
        c = check_pressure_command(values, 1, 5e4, policy)
        assert c.status == "rejected" and c.pressures is None and fragment in c.reason


def test_out_of_range_policy():
    c = check_pressure_command([-5.0], 1, 5e4, "reject")
    assert c.status == "rejected" and "negative" in c.reason
    c = check_pressure_command([6e4], 1, 5e4, "clamp")
    assert c.status == "clamped" and c.pressures.tolist() == [5e4] and "exceeds" in c.reason
    c = check_pressure_command([-1.0, 7e4], 2, 5e4, "clamp")
    np.testing.assert_array_equal(c.pressures, [0.0, 5e4])
    with pytest.raises(ValueError):
        check_pressure_command([1.0], 1, 5e4, "ignore")
