"""Tests of vjm_pin.viz.viewer: scene geometry, animation commands, and the exported page
rendered in headless Chromium (skipped when no chromium binary is installed)."""

from __future__ import annotations

import itertools

import numpy as np
import pinocchio as pin
import pytest

from vjm_pin.exceptions import FrameNotFound, InputError, JointNotFound, RoleError
from vjm_pin.viz.viewer import (
    STABLE_COLOR,
    STYLE_COLORS,
    Animation,
    chain_geometry,
    default_scale,
    export_html,
    magnify,
)

from .browser import chromium, screenshot_grid

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
    # the force arrow grows with the load; the forces push the tip back along the chain
    # (-x), so the arrow is drawn outside it: on the force line through the tip, ending just
    # short of the tip and pointing at it
    shaft = [k["value"][1] for k in tracks["/meshcat/vjm/force/shaft"][".scale"]]
    assert np.all(np.diff(shaft) > 0)
    assert anim.arrow_style == "head"
    for k in (0, N_FRAMES - 1):
        tip = anim._frame_oMf[k][:3, 3]
        tail = np.array(tracks["/meshcat/vjm/force"][".position"][k]["value"])
        f = forces[k] / np.linalg.norm(forces[k])
        to_tip = tip - tail
        assert np.linalg.norm(np.cross(to_tip, f)) < 1e-9 * np.linalg.norm(to_tip)  # on the line
        assert to_tip @ f > shaft[k]  # the whole arrow (shaft + head) lies before the tip
    # a pull (+x, away from the chain) starts at the tip instead
    pull = Animation(
        model,
        geom,
        frames,
        forces=[-f for f in forces],
        frame_name="tool",
        critical_index=BEND_FRAME,
    )
    assert pull.arrow_style == "tail"
    ptracks = _animation_tracks(pull)
    for k in (0, N_FRAMES - 1):
        tip = pull._frame_oMf[k][:3, 3]
        tail = np.array(ptracks["/meshcat/vjm/force"][".position"][k]["value"])
        assert np.linalg.norm(tail - tip) < 0.05 * pull.scene_size
        assert (tail - tip) @ (-forces[k]) > 0


def test_animation_loads_closures_ellipsoid_and_unstable_parts(chain):
    """Dead-load arrows at their frames (one length scale for all arrows), closure markers
    following their frames, the ellipsoid scaled per frame, and on an unstable frame with a
    mode only the bodies that the mode moves are red."""
    model, geom = chain
    frames, stable, forces = bending_motion(model)
    n = len(frames)
    mode = np.zeros((model.nq, 1))
    mode[2, 0] = 1.0  # only j3 turns: its link (j3 -> tool) moves, the others stay
    rot = np.linalg.qr(np.random.default_rng(1).standard_normal((3, 3)))[0]
    rot[:, 2] *= np.sign(np.linalg.det(rot))
    ell = [None] + [(np.array([0.1, 0.05, 0.02]) * (1 + 0.1 * k), rot) for k in range(1, n)]
    anim = Animation(
        model,
        geom,
        frames,
        stable=stable,
        forces=forces,
        frame_name="tool",
        loads=[("l2", [np.array([0.0, 0.0, -25.0 * (k + 1)]) for k in range(n)])],
        closures=[("c", "tool", "l2")],
        modes=[None if s else mode for s in stable],
        ellipsoid=ell,
        ellipsoid_label="test ellipsoid",
    )
    tracks = _animation_tracks(anim)
    data = model.createData()
    for k in (1, n - 1):
        pin.framesForwardKinematics(model, data, frames[k])
        l2 = data.oMf[model.getFrameId("l2")].translation
        tool = data.oMf[model.getFrameId("tool")].translation
        # the load arrow sits on the force line through its frame; half the end force's length
        tail = np.array(tracks["/meshcat/vjm/load0"][".position"][k]["value"])
        assert np.linalg.norm(np.cross(tail - l2, [0, 0, 1])) < 1e-9
        head = 0.2 * anim.arrow_length

        length = {  # shaft + (scaled) head
            node: tracks[f"/meshcat/vjm/{node}/shaft"][".scale"][k]["value"][1]
            + tracks[f"/meshcat/vjm/{node}/head"][".scale"][k]["value"][1] * head
            for node in ("load0", "force")
        }
        assert length["load0"] == pytest.approx(0.5 * length["force"], rel=1e-9)
        # closure markers: frame_b and frame_a
        np.testing.assert_allclose(tracks["/meshcat/vjm/closure0/b"][".position"][k]["value"], l2, atol=1e-12)
        np.testing.assert_allclose(tracks["/meshcat/vjm/closure0/a"][".position"][k]["value"], tool, atol=1e-12)
        # the ellipsoid: centred at the end frame, scaled by its semi-axes
        np.testing.assert_allclose(tracks["/meshcat/vjm/ellipsoid"][".position"][k]["value"], tool, atol=1e-12)
        np.testing.assert_allclose(tracks["/meshcat/vjm/ellipsoid/shape"][".scale"][k]["value"], ell[k][0], rtol=1e-12)
    visible = [key["value"] for key in tracks["/meshcat/vjm/ellipsoid"][".visible"]]
    assert visible == [False] + [True] * (n - 1)
    # unstable frames: the link moved by the mode is red, the links before it stay green
    anim_red = [0.9, 0.1, 0.1]
    moved = tracks["/meshcat/vjm/robot/link:j3->tool_joint/<object>"][".material.color"]
    still = tracks.get("/meshcat/vjm/robot/link:j1->j2/<object>", {}).get(".material.color")
    assert next(key["value"] for key in moved if key["time"] >= BEND_FRAME) == pytest.approx(anim_red)
    assert still is None  # never changes colour: green on every frame
    setup = anim.page_setup()
    texts = [e["text"] for e in setup["legend"]]
    assert "test ellipsoid" in texts and any("loop closure" in t for t in texts)
    assert any("take part in its unstable mode" in t for t in texts)
    load = next(a for a in setup["anchors"] if a["cls"] == "load")
    assert load["text"][3] == "l2: 100 N"


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


@pytest.mark.parametrize(
    "bad,words",
    [([1.0, 2.0, 3.0, 4.0], "3 or 6 components"), ([1.0, float("nan"), 0.0], "NaN"), ("abc", "numbers")],
)
def test_animation_forces_are_three_or_six_finite_numbers(chain, bad, words):
    """The "3 or 6 numbers" check of ``forces`` is task_vector's (one line naming the entry);
    a wrench draws its force part."""
    model, geom = chain
    frames, _, forces = bending_motion(model)
    given = list(forces)
    given[1] = bad
    with pytest.raises(InputError, match=rf"forces\[1\].*{words}|{words}.*forces\[1\]") as e:
        Animation(model, geom, frames, forces=given, frame_name="tool")
    assert "\n" not in str(e.value)
    wrenches = [np.concatenate([f, [7.0, -8.0, 9.0]]) for f in forces]
    anim = Animation(model, geom, frames, forces=wrenches, frame_name="tool")
    for got, f in zip(anim.forces, forces):
        np.testing.assert_allclose(got, np.asarray(f, float)[:3], rtol=0, atol=0)


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
    img = screenshot_grid(browser, {k: (page, k) for k in (0, 15)}, tmp_path, cell=(800, 600))
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
    from vjm_pin.model.registry import resolve_model

    vm = resolve_model("ur5")
    geom = robot_geometry(vm)
    files = [g.meshPath for g in geom.geometryObjects]
    assert geom.ngeoms >= 6 and any(f.endswith(".dae") for f in files)
    chain = resolve_model("paper-c-s")
    assert all(
        not g.meshPath.endswith((".dae", ".stl")) for g in robot_geometry(chain).geometryObjects
    )


# ----------------------------------------------------------------------------- curve pages
# The paper's Model C chain in the S posture under end compression: the straight column is
# axially stiff, so the critical point falls inside the first even curve step.
PAPER = "paper-c-s"
COMPRESS = np.array([-1.0, 0, 0, 0, 0, 0])
MAX_DEFLECTION, STEPS, N_CURVE_FRAMES = 0.05, 20, 61


@pytest.fixture(scope="module")
def c_model():
    from vjm_pin.model.registry import resolve_model

    return resolve_model(PAPER)


@pytest.fixture(scope="module")
def c_curve_all(c_model):
    from vjm_pin.analysis.curve import trace_curve

    return trace_curve(c_model, COMPRESS, MAX_DEFLECTION, STEPS, all_branches=True)


@pytest.fixture(scope="module")
def c_page(c_model, c_curve_all, tmp_path_factory):
    from vjm_pin.cli.view import curve_page

    path = tmp_path_factory.mktemp("curve") / "c.html"
    cp = curve_page(c_model, c_curve_all, path=path, n_frames=N_CURVE_FRAMES)
    return path, cp


def _joints(vm, x) -> np.ndarray:
    data = vm.model.createData()
    pin.forwardKinematics(vm.model, data, np.asarray(x, float))
    return np.array([m.translation for m in data.oMi[1:]])


def _shape_steps(vm, xs) -> np.ndarray:
    """Largest joint displacement (m) between consecutive configurations."""
    j = [_joints(vm, x) for x in xs]
    return np.array([np.linalg.norm(b - a, axis=1).max() for a, b in itertools.pairwise(j)])


def _page_setup(text: str) -> dict:
    import json
    import re

    return json.loads(re.search(r"var setup = (\{.*?\});\n", text, re.DOTALL).group(1))


def test_curve_frames_show_the_buckling_in_slow_motion(c_model, c_curve_all, c_page):
    _, cp = c_page
    frames, k = list(cp.curve_frames), cp.critical_frame
    c = c_curve_all.critical[0]
    h = MAX_DEFLECTION / STEPS
    assert c.deflection < h  # even curve steps: the critical point is inside the first one
    s = np.array([f.deflection for f in frames])
    assert np.all(np.diff(s) > 0)
    # the critical frame is the pre-critical state at the critical deflection (force too)
    assert frames[k].kind == "critical"
    assert frames[k].deflection == pytest.approx(c.deflection, rel=1e-3)
    assert frames[k].force == pytest.approx(c.force, rel=1e-3)
    # both the pre-critical rise and the start of the buckling get many frames (even
    # deflection frames would give them one step)
    assert k >= 10
    assert np.sum((s > c.deflection) & (s < c.deflection + h)) >= 8
    # past the critical point the shape changes much faster than before it (where the chain
    # only shortens), and no frame step carries more than a fifth of the whole change
    steps = _shape_steps(c_model, [f.x for f in frames])
    assert steps[k : k + 4].max() > 10 * steps[k - 5 : k - 1].max()
    total = np.linalg.norm(
        _joints(c_model, frames[-1].x) - _joints(c_model, frames[0].x), axis=1
    ).max()
    assert steps.max() < 0.2 * total


def test_curve_frames_are_equilibria(c_model, c_page):
    """Each frame re-solved independently (warm start from its predecessor's state, the way a
    curve is traced) is the same equilibrium. Frames just past the bifurcation are skipped:
    from the straight state the solver may pick the mirror-image bend."""
    from vjm_pin.solver import EquilibriumSolver

    _, cp = c_page
    frames, k = list(cp.curve_frames), cp.critical_frame
    solver = EquilibriumSolver(c_model)
    picks = sorted(set(range(1, len(frames), 7)) - {k + 1} | {k, k + 2, k + 3})
    for i in picks:
        prev, f = frames[i - 1], frames[i]
        eq = solver.solve(f.deflection * COMPRESS, x0=prev.x, wrench0=prev.wrench)
        assert eq.converged
        np.testing.assert_allclose(eq.x, f.x, atol=1e-6, err_msg=f"frame {i}")
        assert float(COMPRESS @ eq.wrench) == pytest.approx(f.force, rel=1e-5, abs=1e-9)


def test_other_branches_are_unstable_equilibria(c_model, c_curve_all, c_page):
    from vjm_pin.cli.view import branch_frames
    from vjm_pin.solver import EquilibriumSolver

    _, cp = c_page
    frames, k = list(cp.curve_frames), cp.critical_frame
    branches = branch_frames(c_model, c_curve_all, frames)
    assert len(branches) >= 1 and cp.branches == len(branches)
    unstable = EquilibriumSolver(c_model, follow_stable=False)
    for b in branches:
        shown = [i for i, q in enumerate(b.frames) if q is not None]
        assert len(shown) > len(frames) // 3 and min(shown) >= k  # from the critical point on
        for i in shown[:: max(1, len(shown) // 5)]:
            assert not b.stable[i]
            eq = unstable.solve(frames[i].deflection * COMPRESS, x0=b.frames[i])
            assert eq.converged and eq.stable is False
            np.testing.assert_allclose(eq.x, b.frames[i], atol=1e-6)
        # far past the critical point it is another configuration than the followed branch
        assert (
            np.linalg.norm(_joints(c_model, b.frames[-1]) - _joints(c_model, frames[-1].x)) > 0.05
        )


def test_curve_page_setup_slider_legend_labels(c_page, c_curve_all):
    path, cp = c_page
    setup = _page_setup(path.read_text(encoding="utf-8"))
    frames = cp.curve_frames
    n = cp.frames
    assert setup["nframes"] == n and len(setup["labels"]) == n
    # the load slider is in mm of deflection, one value per frame, increasing
    sl = setup["slider"]
    assert sl["unit"] == "mm" and len(sl["values"]) == n
    np.testing.assert_allclose(
        sl["values"][-len(frames) :], [f.deflection * 1e3 for f in frames], rtol=1e-12
    )
    assert np.all(np.diff(sl["values"]) > 0)
    # legend: stable, unstable (the other branch), critical, force
    texts = " ".join(e["text"] for e in setup["legend"])
    for word in ("stable", "unstable", "critical", "force"):
        assert word in texts
    # the critical label names the force in N; the force labels follow the frames' forces
    crit = next(a for a in setup["anchors"] if a["cls"] == "critical")
    f_cr = float(crit["text"][0].split("F_cr = ")[1].split(" N")[0])
    assert f_cr == pytest.approx(abs(c_curve_all.critical[0].force), rel=1e-3)
    force = next(a for a in setup["anchors"] if a["cls"] == "force")
    k = cp.critical_frame
    shown_f = float(force["text"][k].split("F = ")[1].split(" N")[0])
    assert shown_f == pytest.approx(
        np.linalg.norm(frames[k - (n - len(frames))].wrench[:3]), rel=1e-2
    )


# ----------------------------------------------------------------------------- load path
def test_view_wrench_frames_are_equilibria_along_the_load_path(tmp_path, capsys):
    """``view ur5 --wrench``: every frame is the equilibrium under its own share of the load
    (re-solved from the unloaded robot, independently of the warm-started path), and its
    label and slider value give that load in N."""
    from vjm_pin.cli import main
    from vjm_pin.model.registry import resolve_model
    from vjm_pin.solver import EquilibriumSolver

    page = tmp_path / "ur5.html"
    w = np.array([0.0, 0.0, -300.0, 0.0, 0.0, 0.0])
    assert main(["view", "ur5", "--wrench", *map(str, w[:3]), "--html", str(page)]) == 0
    capsys.readouterr()
    setup = _page_setup(page.read_text(encoding="utf-8"))
    n = setup["nframes"]
    assert n >= 11
    vm = resolve_model("ur5")
    solver = EquilibriumSolver(vm)
    ts = np.linspace(0.0, 1.0, n)
    for k in (3, n // 2, n - 1):
        cold = solver.solve_wrench(ts[k] * w)
        shown = float(setup["labels"][k].split("|F| = ")[1].split(" N")[0])
        assert shown == pytest.approx(ts[k] * 300.0, rel=1e-3)
        assert setup["slider"]["values"][k] == pytest.approx(ts[k] * 300.0, rel=1e-6)
        dmm = float(setup["labels"][k].split("|δ| = ")[1].split(" mm")[0])
        assert dmm == pytest.approx(np.linalg.norm(cold.deflection[:3]) * 1e3, rel=1e-3)
    # the frames themselves (API): configurations equal the independent solves
    from vjm_pin.cli.view import load_path

    ts2, path = load_path(vm, w, "wrench", n=5)
    for t, eq in zip(ts2, path):
        np.testing.assert_allclose(eq.wrench, t * w, atol=1e-3)
        np.testing.assert_allclose(eq.x, solver.solve_wrench(t * w).x, atol=1e-7)


def test_view_deflection_frames_label_their_true_force(tmp_path, capsys):
    """paper-a-s: the old page labelled linear joint-space interpolations "load ×t"; now
    each frame's label gives the force of the equilibrium at t·δ, solved independently."""
    from vjm_pin.cli import main
    from vjm_pin.model.registry import resolve_model
    from vjm_pin.solver import EquilibriumSolver

    page = tmp_path / "a.html"
    d = np.array([-0.003, 0.0, 0.0])
    assert main(["view", "paper-c-s", "--deflection", *map(str, d), "--html", str(page)]) == 0
    capsys.readouterr()
    setup = _page_setup(page.read_text(encoding="utf-8"))
    n = setup["nframes"]
    vm = resolve_model("paper-c-s")
    solver = EquilibriumSolver(vm)
    ts = np.linspace(0.0, 1.0, n)
    forces = []
    for k in range(1, n):
        shown = float(setup["labels"][k].split("|F| = ")[1].split(" N")[0])
        forces.append(shown)
        if k % 5 == 0:
            eq = solver.solve(ts[k] * d)
            assert shown == pytest.approx(np.linalg.norm(eq.wrench[:3]), rel=2e-3)
        assert setup["slider"]["values"][k] == pytest.approx(ts[k] * 3.0, rel=1e-6)  # mm
    assert "unloaded" in setup["labels"][0]


# ----------------------------------------------------------------------------- browser: models
CELL = (480, 360)  # pixels of each picture of the grid screenshot


def _marker_masks(img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels of the force arrow (yellow) and the critical marker (magenta)."""
    r, g, b = (img[..., i].astype(int) for i in range(3))
    return (r > 180) & (g > 150) & (b < 90), (r > 160) & (b > 160) & (g < 90)


def _assert_in_frame(img: np.ndarray, what: str, min_span: float = 0.6) -> None:
    """The robot is there; it, its force arrow and marker span a good part of the picture;
    none of them is cut at the borders."""
    green, red = _colour_masks(img)
    robot = green | red
    scene = robot | np.logical_or(*_marker_masks(img))
    h, w = robot.shape
    assert robot.sum() > 800, f"{what}: robot not visible ({robot.sum()} pixels)"
    rows, cols = np.nonzero(scene.any(axis=1))[0], np.nonzero(scene.any(axis=0))[0]
    span = max((cols.max() - cols.min()) / w, (rows.max() - rows.min()) / h)
    assert span > min_span, f"{what}: robot spans only {span:.0%} of the picture"
    edge = np.zeros_like(scene)
    edge[:3], edge[-3:], edge[:, :3], edge[:, -3:] = True, True, True, True
    assert (scene & edge).sum() < 10, (
        f"{what}: cut at the border ({(scene & edge).sum()} pixels there)"
    )


@pytest.fixture(scope="module")
def model_shots(c_page, tmp_path_factory):
    """One Chromium run: the paper chain's curve page (with its other branch) around the
    critical frame, and ``view ur5 --wrench 0 0 -300`` unloaded and loaded."""
    browser = chromium()
    if browser is None:
        pytest.skip("no chromium binary on PATH (apt-get install chromium)")
    from vjm_pin.cli import main

    tmp = tmp_path_factory.mktemp("shots")
    ur5 = tmp / "ur5.html"
    assert main(["view", "ur5", "--wrench", "0", "0", "-300", "--html", str(ur5)]) == 0
    n_ur5 = _page_setup(ur5.read_text(encoding="utf-8"))["nframes"]
    path, cp = c_page
    k, last = cp.critical_frame, cp.frames - 1
    shots = {("c", i): (path, i) for i in (k - 6, k - 3, k, k + 3, last)}
    shots[("ur5", 1)] = (ur5, n_ur5 - 1)  # one ur5 picture: its page is large (meshes)
    return screenshot_grid(browser, shots, tmp, cell=CELL), k, last


def test_browser_paper_chain_curve_buckling(model_shots):
    img, k, last = model_shots
    c = {i: a for (m, i), a in img.items() if m == "c"}
    for i, a in c.items():
        _assert_in_frame(a, f"paper chain frame {i}")
    green = {i: _colour_masks(a)[0] for i, a in c.items()}
    red = {i: _colour_masks(a)[1] for i, a in c.items()}
    # the critical frame differs visibly from its successor: the silhouette of the stable
    # robot changes much more across the critical point than over as many pre-critical frames
    across = (green[k] ^ green[k + 3]).sum()
    before = (green[k - 6] ^ green[k - 3]).sum()
    assert across > 3 * before + 150, (before, across)
    # the critical marker is visible (not hidden under the end sphere) on every frame
    for i, a in c.items():
        assert _marker_masks(a)[1].sum() > 150, f"frame {i}: no critical marker"
    # the other branch (the straight column, unstable past the critical point) is red
    assert red[last].sum() > 400 and red[k - 3].sum() < 50, (red[k - 3].sum(), red[last].sum())


def test_browser_ur5_wrench_in_frame(model_shots):
    img, _, _ = model_shots
    u1 = img[("ur5", 1)]
    _assert_in_frame(u1, "ur5 under 300 N")
    assert _marker_masks(u1)[0].sum() > 100  # its force arrow is drawn


def test_all_branches_needs_curve(tmp_path, capsys):
    from vjm_pin.cli import main

    out = tmp_path / "x.html"
    assert (
        main(
            [
                "view",
                PAPER,
                "--deflection",
                "-0.001",
                "0",
                "0",
                "--all-branches",
                "--html",
                str(out),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert err.startswith("vjm-pin: error:") and "--all-branches" in err and err.count("\n") == 1
    assert not out.exists()


# ----------------------------------------------------------------------------- browser: mechanisms
@pytest.fixture(scope="module")
def mechanism_shots(tmp_path_factory):
    """One Chromium run: a closed loop's curve page around its critical frame with the
    continued (unstable) branch (tests/roller_column.py), the portal frame under vertical
    dead loads across its sway buckling load, and the Orthoglide at Q3 across its critical
    force along −u (``view orthoglide-q3 --wrench -2300 -2300 -2300``)."""
    browser = chromium()
    if browser is None:
        pytest.skip("no chromium binary on PATH (apt-get install chromium)")
    from vjm_pin.analysis.curve import trace_curve
    from vjm_pin.cli import main
    from vjm_pin.cli.view import curve_page
    from vjm_pin.model.registry import resolve_model

    from .roller_column import roller_column

    tmp = tmp_path_factory.mktemp("mechanism-shots")
    vm = resolve_model(str(roller_column(tmp)))
    roller = tmp / "roller.html"
    cp = curve_page(vm, trace_curve(vm, [-1.0, 0, 0], 0.3, 12), path=roller, n_frames=61,
                    all_branches=True)
    k, last = cp.critical_frame, cp.frames - 1
    portal, ortho = tmp / "portal.html", tmp / "q3.html"
    loads = ["--load", "top_left", "0", "0", "-300", "--load", "top_right", "0", "0", "-300"]
    assert main(["view", "portal-frame", *loads, "--html", str(portal)]) == 0
    assert main(["view", "orthoglide-q3", "--wrench", "-2300", "-2300", "-2300", "--html", str(ortho)]) == 0
    shots = {("roller", i): (roller, i) for i in (k - 6, k - 3, k, k + 3, last)}
    # 21 frames at load factors 0, 0.05, ...: the portal turns unstable between 13 and 14
    # (P = 195 and 210 N, 2k/h = 200 N), the Orthoglide between 17 and 18 (3.39 and 3.58 kN)
    shots.update({("portal", i): (portal, i) for i in (13, 14)})
    shots.update({("ortho", i): (ortho, i) for i in (17, 18, 20)})
    return screenshot_grid(browser, shots, tmp, cell=CELL), k, last


def test_browser_closed_loop_curve_buckling(mechanism_shots):
    img, k, last = mechanism_shots
    r = {i: a for (m, i), a in img.items() if m == "roller"}
    for i, a in r.items():
        _assert_in_frame(a, f"roller column frame {i}")
        assert _marker_masks(a)[1].sum() > 150, f"frame {i}: no critical marker"
    green = {i: _colour_masks(a)[0] for i, a in r.items()}
    red = {i: _colour_masks(a)[1] for i, a in r.items()}
    # the followed column bends past the critical frame; before it, it only shortens
    across = (green[k] ^ green[k + 3]).sum()
    before = (green[k - 6] ^ green[k - 3]).sum()
    assert across > 3 * before + 150, (before, across)
    # the straight branch it leaves is drawn in red past the critical point only
    assert red[last].sum() > 400 and red[k + 3].sum() > 200, (red[k + 3].sum(), red[last].sum())
    assert red[k - 3].sum() < 50 and red[k].sum() < 50, (red[k - 3].sum(), red[k].sum())


def test_browser_portal_frame_sway_parts_in_red(mechanism_shots):
    img, _, _ = mechanism_shots
    below, above = img[("portal", 13)], img[("portal", 14)]
    for name, a in (("below", below), ("above", above)):
        _assert_in_frame(a, f"portal frame {name} the buckling load")
        assert _marker_masks(a)[0].sum() > 100, f"{name}: no load arrows"
    g0, r0 = _colour_masks(below)
    g1, r1 = _colour_masks(above)
    assert r0.sum() < 50 and g0.sum() > 3000, (g0.sum(), r0.sum())
    # past 2k/h the columns and the beam (they sway) turn red; the ground link stays green
    assert r1.sum() > 3000 and 200 < g1.sum() < 0.5 * g0.sum(), (g1.sum(), r1.sum())


def test_browser_orthoglide_buckling_leg_in_red(mechanism_shots):
    img, _, _ = mechanism_shots
    o = {i: a for (m, i), a in img.items() if m == "ortho"}
    for i, a in o.items():
        _assert_in_frame(a, f"Orthoglide Q3 frame {i}", min_span=0.5)
    g17, r17 = _colour_masks(o[17])
    assert r17.sum() < 50 and g17.sum() > 1000, (g17.sum(), r17.sum())
    for i in (18, 20):  # one leg red (the one that buckles), the two others green
        g, r = _colour_masks(o[i])
        assert r.sum() > 300 and g.sum() > 0.5 * g17.sum(), (i, g.sum(), r.sum())
