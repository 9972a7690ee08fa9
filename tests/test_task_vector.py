"""The one "3 or 6 numbers, finite, in the task" check (vjm_pin.model.task)."""

from __future__ import annotations

import numpy as np
import pytest

from vjm_pin.exceptions import InputError
from vjm_pin.model.task import task_vector


def test_three_numbers_are_the_translation():
    v = task_vector([1.0, -2.0, 3e-3])
    assert v.shape == (6,)
    np.testing.assert_array_equal(v, [1.0, -2.0, 3e-3, 0.0, 0.0, 0.0])


def test_task_sized_vector_is_scattered_into_the_task_components():
    v = task_vector([4.0, 5.0], task=(0, 2), name="wrench", unit="N", task_sized=True)
    np.testing.assert_array_equal(v, [4.0, 0.0, 5.0, 0.0, 0.0, 0.0])
    with pytest.raises(InputError, match="3 or 6 components .*got 2"):
        task_vector([4.0, 5.0], task=(0, 2))  # not allowed unless task_sized


@pytest.mark.parametrize(
    "values, match",
    [
        ([1.0, 2.0], "3 or 6 components"),
        ([1.0, np.nan, 0.0], "NaN or infinite"),
        ([1.0, 0.0, np.inf, 0, 0, 0], "NaN or infinite"),
        ("abc", "must be numbers"),
    ],
)
def test_bad_vectors_are_refused_with_one_line(values, match):
    with pytest.raises(InputError, match=match) as info:
        task_vector(values, name="deflection")
    assert "\n" not in str(info.value) and "deflection" in str(info.value)


def test_components_outside_the_task_are_refused_or_kept():
    with pytest.raises(InputError, match=r"\['y'\] outside the task \['x', 'z'\]"):
        task_vector([0.0, 1e-3, 0.0], task=(0, 2), name="deflection")
    v = task_vector([0.0, 1e-3, 0.0], task=(0, 2), outside_task="keep")
    assert v[1] == 1e-3
    # zero components outside the task are fine
    np.testing.assert_array_equal(task_vector([1.0, 0.0, 2.0], task=(0, 2)), [1, 0, 2, 0, 0, 0])


def test_three_numbers_on_a_three_component_task_are_its_components():
    # task (x, z, ry): (fx, fz, my), not a translation that would put my into fz
    v = task_vector([10.0, 0.0, 5.0], task=(0, 2, 4), task_sized=True)
    np.testing.assert_array_equal(v, [10.0, 0.0, 0.0, 0.0, 5.0, 0.0])
    # the translational task reads the same either way
    np.testing.assert_array_equal(task_vector([1.0, 2.0, 3.0], task=(0, 1, 2), task_sized=True), [1, 2, 3, 0, 0, 0])
