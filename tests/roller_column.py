"""A closed loop that buckles under deflection control, for the viewer tests.

The paper's Model A column (three rigid 1 m links, a passive base pivot, rotational springs
k = 1 N·m/rad at the two inner joints) on an axial base spring (k_a = 1000 N/m), its end on a
roller: a ``<vjm:closure>`` holds the end's y on a ground frame at (3, 0, 0). Compressed
along −x the straight column is a pinned–pinned column with two spring joints: with the joint
offsets y1, y2, the spring energy ½[(y2 − 2y1)² + (y1 − 2y2)²] and the shortening
½[y1² + (y2 − y1)² + y2²] give the buckling loads P = 1 N (y1 = y2) and 3 N (y1 = −y2); the
first is reached at δ = P/k_a = 1 mm. Past it the straight branch goes on, unstable.
"""

from __future__ import annotations

#: Critical force (N) and deflection (m) of the closed form above.
CRITICAL_FORCE, CRITICAL_DEFLECTION = 1.0, 1e-3

ROLLER_URDF = """<robot xmlns:vjm="urn:vjm-pin:1" name="roller-column">
  <link name="base" /><link name="slide" /><link name="link1" /><link name="link2" />
  <link name="link3" /><link name="end" /><link name="anchor" />
  <joint name="base_x" type="prismatic"><parent link="base" /><child link="slide" />
    <axis xyz="1 0 0" /><limit lower="-1000.0" upper="1000.0" effort="0" velocity="0" /></joint>
  <joint name="base_z" type="revolute"><parent link="slide" /><child link="link1" />
    <axis xyz="0 0 1" /><limit lower="-1000.0" upper="1000.0" effort="0" velocity="0" /></joint>
  <joint name="qa1" type="revolute"><parent link="link1" /><child link="link2" />
    <origin xyz="1.0 0 0" /><axis xyz="0 0 1" />
    <limit lower="-1000.0" upper="1000.0" effort="0" velocity="0" /></joint>
  <joint name="qa2" type="revolute"><parent link="link2" /><child link="link3" />
    <origin xyz="1.0 0 0" /><axis xyz="0 0 1" />
    <limit lower="-1000.0" upper="1000.0" effort="0" velocity="0" /></joint>
  <joint name="end_joint" type="fixed"><parent link="link3" /><child link="end" />
    <origin xyz="1.0 0 0" /></joint>
  <joint name="anchor_joint" type="fixed"><parent link="base" /><child link="anchor" />
    <origin xyz="3.0 0 0" /></joint>
  <vjm:task frame="end" components="x" />
  <vjm:joint name="base_x" role="actuated" stiffness="1000.0" position="0.0" />
  <vjm:joint name="base_z" role="passive" position="0.0" />
  <vjm:joint name="qa1" role="actuated" stiffness="1.0" position="0.0" />
  <vjm:joint name="qa2" role="actuated" stiffness="1.0" position="0.0" />
  <vjm:closure name="roller" frame_a="end" frame_b="anchor" components="y" />
</robot>
"""


def roller_column(folder):
    """Write the model to ``folder/roller-column.urdf`` and return the path."""
    path = folder / "roller-column.urdf"
    path.write_text(ROLLER_URDF, encoding="utf-8")
    return path
