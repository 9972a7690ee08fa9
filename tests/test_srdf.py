"""SRDF named states through Pinocchio's reader (vjm_pin.model.robots.srdf_states)."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import pytest

from vjm_pin.exceptions import ModelError
from vjm_pin.model.robots import _strip_transmissions, robot_source, srdf_states


@pytest.mark.parametrize("name", ["panda", "kinova", "solo12"])
def test_states_hold_the_values_the_srdf_lists(name):
    src = robot_source(name)
    text = _strip_transmissions(src.urdf)
    states = srdf_states(src.srdf, text)
    root = ET.parse(src.srdf).getroot()
    listed = 0
    for gs in root.findall("group_state"):
        for j in gs.findall("joint"):
            if j.get("name") not in states[gs.get("name")]:
                continue  # a joint the URDF does not have as a 1-DOF joint
            want = float(j.get("value").split()[0])
            got = states[gs.get("name")][j.get("name")]
            # a continuous joint comes back as its angle in (-π, π]
            diff = math.remainder(got - want, 2 * math.pi)
            assert abs(diff) < 1e-9, (gs.get("name"), j.get("name"), got, want)
            listed += 1
    assert listed >= 6


def test_unreadable_srdf_is_one_line(tmp_path):
    src = robot_source("panda")
    bad = tmp_path / "bad.srdf"
    bad.write_text("<robot><group_state name='x' group='g'><joint name='nope' value='1'/>")
    with pytest.raises(ModelError) as info:
        srdf_states(bad, _strip_transmissions(src.urdf))
    assert "\n" not in str(info.value) and str(bad) in str(info.value)
