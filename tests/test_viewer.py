"""Tests of vjm_pin.viewer: scene geometry, animation commands, and the exported page
rendered in headless Chromium (skipped when no chromium binary is installed)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from vjm_pin.exceptions import FrameNotFound, InputError, JointNotFound, RoleError
from vjm_pin.viewer import (
    STABLE_COLOR,
    STYLE_COLORS,
    Animation,
    chain_geometry,
    default_scale,
    export_html,
    magnify,
)

from .browser import chromium, screenshot_frames

# Three revolute joints, links of 0.4 m along x; j2 bends the chain out of the xy plane.
CHAIN_URDF = """<robot name="chain3">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="tool"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.4 0 0"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.4 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="tool_joint" type="fixed"><parent link="l3"/><child link="tool"/>
    <origin xyz="0.4 0 0"/></joint>
</robot>"""

# Like a generated VJM chain: a spring stack (tx at the link tip, ty and rz at the same
# point) followed by the passive joint j2 at that point too.
STACKED_URDF = """<robot name="stacked">
  <link name="base"/><link name="l1"/><link name="f_tx"/><link name="f_ty"/><link name="f_rz"/>
  <link name="l2"/><link name="tool"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="s_tx" type="prismatic"><parent link="l1"/><child link="f_tx"/>
    <origin xyz="0.5 0 0"/><axis xyz="1 0 0"/><limit lower="-1" upper="1" effort="0" velocity="0"/></joint>
  <joint name="s_ty" type="prismatic"><parent link="f_tx"/><child link="f_ty"/>
    <origin xyz="0 0 0"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="0" velocity="0"/></joint>
  <joint name="s_rz" type="revolute"><parent link="f_ty"/><child link="f_rz"/>
    <origin xyz="0 0 0"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="0" velocity="0"/></joint>
  <joint name="j2" type="revolute"><parent link="f_rz"/><child link="l2"/>
    <origin xyz="0 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="tool_joint" type="fixed"><parent link="l2"/><child link="tool"/>
    <origin xyz="0.3 0 0"/></joint>
</robot>"""

N_FRAMES = 20
BEND_FRAME = 10


@pytest.fixture(scope="module")
def chain():
    model = pin.buildModelFromXML(CHAIN_URDF)
    geom = chain_geometry(model, {"j1": "actuated", "j2": "passive", "j3": "spring"})
    return model, geom


def bending_motion(model: pin.Model):
    """20 frames: slow in-plane motion, then from frame 10 a sudden out-of-plane bend (j2).

    Returns frames (nq each, rad), stability flags and tip forces (N, world axes)."""
    frames, stable, forces = [], [], []
    for k in range(N_FRAMES):
        q = np.zeros(model.nq)
        q[0] = 0.3 * k / N_FRAMES
        q[2] = 0.2 * k / N_FRAMES
        if k >= BEND_FRAME:
            q[1] = -0.9 - 0.02 * (k - BEND_FRAME)  # tip goes up (+z)
        frames.append(q)
        stable.append(k < BEND_FRAME)
        forces.append(np.array([-50.0 * (k + 1), 0.0, 0.0]))
    return frames, stable, forces


def _animation_tracks(anim: Animation) -> dict[str, dict[str, list]]:
    """path -> track name -> keys of the SetAnimation command."""
    cmd = [c for c in anim.commands() if type(c).__name__ == "_SetAnimationAt"]
    assert len(cmd) == 1
    out: dict[str, dict[str, list]] = {}
    for entry in cmd[0].lower()["animations"]:
        out[entry["path"]] = {t["name"]: t["keys"] for t in entry["clip"]["tracks"]}
    return out


# ----------------------------------------------------------------------------- geometry
def test_chain_geometry_segments_and_markers(chain):
    model, geom = chain
    names = [o.name for o in geom.geometryObjects]
    assert names == [
        "link:universe->j1",
        "link:j1->j2",
        "link:j2->j3",
        "link:j3->tool_joint",
        "joint:j1",
        "joint:j2",
        "joint:j3",
    ]
    objs = {o.name: o for o in geom.geometryObjects}
    # segment j1 -> j2: 0.4 m long cylinder centred at 0.2 m along x of joint j1
    seg = objs["link:j1->j2"]
    assert seg.parentJoint == model.getJointId("j1")
    assert 2 * seg.geometry.halfLength == pytest.approx(0.4)
    np.testing.assert_allclose(seg.placement.translation, [0.2, 0, 0], atol=1e-12)
    np.testing.assert_allclose(seg.placement.rotation @ [0, 0, 1], [1, 0, 0], atol=1e-12)
    # the tool segment hangs on the leaf joint and reaches the tool frame
    tool = objs["link:j3->tool_joint"]
    assert tool.parentJoint == model.getJointId("j3")
    np.testing.assert_allclose(tool.placement.translation, [0.2, 0, 0], atol=1e-12)
    # the base pillar is static (universe)
    assert objs["link:universe->j1"].parentJoint == 0
    # distinct colours per style
    np.testing.assert_allclose(objs["joint:j1"].meshColor, STYLE_COLORS["actuated"])
    np.testing.assert_allclose(objs["joint:j2"].meshColor, STYLE_COLORS["passive"])
    np.testing.assert_allclose(objs["joint:j3"].meshColor, STYLE_COLORS["spring"])
    assert objs["joint:j2"].geometry.radius > seg.geometry.radius


def test_chain_geometry_skips_stacked_spring_frames():
    model = pin.buildModelFromXML(STACKED_URDF)
    styles = {
        "j1": "actuated",
        "s_tx": "spring",
        "s_ty": "spring",
        "s_rz": "spring",
        "j2": "passive",
    }
    geom = chain_geometry(model, styles, link_shape="box")
    objs = {o.name: o for o in geom.geometryObjects}
    # zero-length segments between the stacked joints are skipped
    assert sorted(n for n in objs if n.startswith("link:")) == [
        "link:j1->s_tx",
        "link:j2->tool_joint",
        "link:universe->j1",
    ]
    # one marker for the stack, passive (it wins over springs), on the deepest joint,
    # with a translucent spring halo
    markers = sorted(n for n in objs if n.startswith("joint:"))
    assert markers == ["joint:j1", "joint:j2", "joint:j2:springs"]
    assert objs["joint:j2"].parentJoint == model.getJointId("j2")
    np.testing.assert_allclose(objs["joint:j2"].meshColor, STYLE_COLORS["passive"])
    assert objs["joint:j2:springs"].meshColor[3] < 1.0
    # chains that only have springs at a point show a spring marker
    geom2 = chain_geometry(
        model, {"j2": "spring", "s_tx": "spring", "s_ty": "spring", "s_rz": "spring"}
    )
    spring_marker = [o for o in geom2.geometryObjects if o.name == "joint:s_tx"]
    assert len(spring_marker) == 1
    np.testing.assert_allclose(spring_marker[0].meshColor, STYLE_COLORS["spring"])


def test_chain_geometry_rejects_bad_styles(chain):
    model, _ = chain
    with pytest.raises(JointNotFound):
        chain_geometry(model, {"nope": "passive"})
    with pytest.raises(RoleError):
        chain_geometry(model, {"j1": "floppy"})
    with pytest.raises(RoleError):
        chain_geometry(model, {}, link_shape="sphere")


# ----------------------------------------------------------------------------- animation
def test_animation_tracks(chain):
    model, geom = chain
    frames, stable, forces = bending_motion(model)
    anim = Animation(
        model,
        geom,
        frames,
        ghost_q=frames[0],
        stable=stable,
        forces=forces,
        frame_name="tool",
        critical_index=BEND_FRAME,
        fps=10,
    )
    tracks = _animation_tracks(anim)
    # moving links are animated, the static base pillar is not
    assert "/meshcat/vjm/robot/link:j2->j3" in tracks
    assert "/meshcat/vjm/robot/link:universe->j1" not in tracks
    pos = tracks["/meshcat/vjm/robot/link:j2->j3"][".position"]
    assert [k["time"] for k in pos] == list(range(N_FRAMES))
    # link colours switch sharply from stable to unstable at the bending frame
    col = tracks["/meshcat/vjm/robot/link:j1->j2/<object>"][".material.color"]
    times = [k["time"] for k in col]
    assert times[0] == 0 and times[-1] == N_FRAMES - 1
    before = [k for k in col if k["time"] < BEND_FRAME]
    after = [k for k in col if k["time"] >= BEND_FRAME]
    assert before[-1]["time"] == pytest.approx(BEND_FRAME, abs=0.01)
    assert all(k["value"] == list(STABLE_COLOR[:3]) for k in before)
    assert all(k["value"] != list(STABLE_COLOR[:3]) for k in after)
    # joint markers keep their style colour
    assert not any(
        p.startswith("/meshcat/vjm/robot/joint:") and p.endswith("<object>") for p in tracks
    )
    # the force arrow follows the tip and grows with the load
    shaft = [k["value"][1] for k in tracks["/meshcat/vjm/force/shaft"][".scale"]]
    assert np.all(np.diff(shaft) > 0)
    tip = anim._frame_oMf[N_FRAMES - 1][:3, 3]
    np.testing.assert_allclose(
        tracks["/meshcat/vjm/force"][".position"][-1]["value"], tip, atol=1e-12
    )


def test_animation_send_matches_commands(chain):
    model, geom = chain
    frames, stable, _ = bending_motion(model)
    anim = Animation(model, geom, frames, stable=stable)

    class Window:
        def __init__(self):
            self.sent = []

        def send(self, cmd):
            self.sent.append(cmd.lower())

    class Vis:
        window = Window()

    anim.send(Vis)
    assert len(Vis.window.sent) == len(anim.commands())
    assert Vis.window.sent[-1]["type"] == "set_animation"


def test_animation_input_errors(chain):
    model, geom = chain
    frames, stable, forces = bending_motion(model)
    with pytest.raises(InputError):
        Animation(model, geom, [np.zeros(2)])
    with pytest.raises(InputError):
        Animation(model, geom, [])
    with pytest.raises(InputError):
        Animation(model, geom, frames, stable=stable[:-1])
    with pytest.raises(InputError):
        Animation(model, geom, frames, forces=forces)  # no frame_name
    with pytest.raises(InputError):
        Animation(model, geom, frames, frame_name="tool", critical_index=N_FRAMES)
    with pytest.raises(InputError):
        Animation(model, geom, frames, fps=0)
    with pytest.raises(FrameNotFound):
        Animation(model, geom, frames, frame_name="hand", critical_index=3)


def test_export_html_is_self_contained(chain, tmp_path):
    model, geom = chain
    frames, stable, forces = bending_motion(model)
    out = tmp_path / "a.html"
    page = export_html(
        model,
        geom,
        frames,
        ghost_q=frames[0],
        stable=stable,
        forces=forces,
        frame_name="tool",
        critical_index=BEND_FRAME,
        title_text="<3R> chain",
        path=out,
    )
    assert out.read_text(encoding="utf-8") == page
    assert "<script src" not in page  # the viewer is inlined
    assert "MeshCat.Viewer" in page and "vjmSeekFrame" in page
    assert "<title>&lt;3R&gt; chain</title>" in page


# ----------------------------------------------------------------------------- browser


def _colour_masks(img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels of the stable (green) and unstable (red) robot colours, as shaded by meshcat."""
    r, g, b = (img[..., i].astype(int) for i in range(3))
    green = (g > 100) & (g > r + 50) & (g > b + 40)
    red = (r > 120) & (g < 70) & (b < 70)
    return green, red


def test_browser_renders_animation(chain, tmp_path):
    browser = chromium()
    if browser is None:
        pytest.skip("no chromium binary on PATH (apt-get install chromium)")

    model, geom = chain
    frames, stable, forces = bending_motion(model)
    page = tmp_path / "chain.html"
    export_html(
        model,
        geom,
        frames,
        ghost_q=frames[0],
        stable=stable,
        forces=forces,
        frame_name="tool",
        critical_index=BEND_FRAME,
        fps=10,
        title_text="3R chain",
        path=page,
    )
    # the page pauses its player at the frame given in the URL fragment
    img = screenshot_frames(browser, page, (0, 15), tmp_path)
    for k, a in img.items():
        assert a.shape == (600, 800, 3)
        assert a.std() > 10, f"frame {k}: blank screenshot"
    green0, red0 = _colour_masks(img[0])
    green15, red15 = _colour_masks(img[15])
    # stable robot in green at frame 0, unstable robot in red at frame 15
    assert green0.sum() > 1500 and red0.sum() < 400, (green0.sum(), red0.sum())
    assert red15.sum() > 1500 and green15.sum() < 400, (green15.sum(), red15.sum())
    # the out-of-plane bend lifts the chain: its topmost pixel is much higher in the picture
    top0 = np.nonzero(green0)[0].min()
    top15 = np.nonzero(red15)[0].min()
    assert top15 < top0 - 80, (top0, top15)
    # the two animation times give different pictures
    diff = np.abs(img[0].astype(int) - img[15].astype(int)).max(axis=2)
    assert (diff > 30).mean() > 0.01


# ----------------------------------------------------------------------------- magnification
def test_magnify_scales_the_deviation_from_the_reference():
    rng = np.random.default_rng(3)
    ref, x = rng.normal(size=7), rng.normal(size=7)
    np.testing.assert_allclose(magnify(ref, x, 1.0), x)
    np.testing.assert_allclose(magnify(ref, ref, 50.0), ref)
    np.testing.assert_allclose(magnify(ref, x, 20.0) - ref, 20.0 * (x - ref))
    # magnifying twice multiplies the scales
    np.testing.assert_allclose(magnify(ref, magnify(ref, x, 3.0), 4.0), magnify(ref, x, 12.0))


@pytest.mark.parametrize("scale", [0.0, -1.0, float("nan"), float("inf")])
def test_magnify_rejects_bad_scale(scale):
    with pytest.raises(InputError, match="scale"):
        magnify(np.zeros(3), np.ones(3), scale)


def test_magnify_rejects_shape_mismatch():
    with pytest.raises(InputError, match="shape"):
        magnify(np.zeros(3), np.ones(4), 2.0)


def test_default_scale_brings_small_deformation_to_view(chain):
    model, _ = chain
    ref = np.zeros(model.nq)
    bent = ref.copy()
    bent[1] = 1e-4  # rad: invisible on a 1.2 m chain
    s = default_scale(model, ref, [ref, bent])
    assert s > 100
    # 1-2-5 numbers only
    mant = s / 10 ** np.floor(np.log10(s))
    assert min(abs(mant - m) for m in (1, 2, 5)) < 1e-9
    # the magnified tip displacement (0.8 m lever arm) is a few percent of the ~1.2 m size
    assert 0.02 < s * 1e-4 * 0.8 / 1.2 < 0.1
    assert default_scale(model, ref, [ref]) == 1.0  # nothing moves
    big = ref.copy()
    big[1] = 0.5
    assert default_scale(model, ref, [big]) == 1.0  # visible already: never shrunk


def test_example_robot_data_robots_show_their_meshes():
    """ur5 from example-robot-data: the VJM URDF keeps its <visual> meshes, and the viewer
    uses them (DAE files resolved through package://); generated chains get primitives."""
    from vjm_pin.cli.view import robot_geometry
    from vjm_pin.registry import resolve_model

    vm = resolve_model("ur5")
    geom = robot_geometry(vm)
    files = [g.meshPath for g in geom.geometryObjects]
    assert geom.ngeoms >= 6 and any(f.endswith(".dae") for f in files)
    chain = resolve_model("paper-c-s")
    assert all(not g.meshPath.endswith((".dae", ".stl")) for g in robot_geometry(chain).geometryObjects)
