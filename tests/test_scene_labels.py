"""Live numbers in meshcat's own page (``serve``): the frame labels drawn as scene text, one
textured square per line, switched per frame by discrete ``visible`` tracks so that at
frame k exactly frame k's lines are shown."""

from __future__ import annotations

import bisect

import numpy as np


def _visible_at(track, t: float) -> bool:
    """The value of a discrete (boolean) track at time ``t``: its last key at or before t."""
    i = bisect.bisect_right(track.frames, t) - 1
    return bool(track.values[max(i, 0)])


def test_scene_text_shows_each_frames_numbers_on_its_frame():
    from vjm_pin.cli.view import load_frames, load_path
    from vjm_pin.model.registry import resolve_model
    from vjm_pin.viz.viewer import Animation, _SetAnimationAt

    vm = resolve_model("paper-c-s")
    ts, path = load_path(vm, np.array([-0.01, 0.002, 0, 0, 0, 0]), "deflection", n=5)
    geom, shown, _, kw = load_frames(vm, ts, path, None, "deflection")
    kw.pop("_meshes")
    anim = Animation(vm.model, geom, shown, ghost_q=vm.reference, frame_name=vm.frame,
                     scene_labels=True, **kw)
    cmds = anim.commands()
    n = len(shown)
    # each frame's lines are its label (force in N, deflection in mm, verdict), as textures
    texts: dict[tuple[int, int], str] = {}
    for c in cmds:
        low = getattr(c, "path", None)
        entries = tuple(low.entries) if low is not None and hasattr(low, "entries") else ()
        if len(entries) == 5 and entries[2] == "text" and type(c).__name__ == "SetObject":
            k, li = int(entries[3][1:]), int(entries[4][1:])
            texts[(k, li)] = c.object.material.map.properties["text"]
    for k in range(n):
        lines = [texts[(k, li)] for li in range(len(anim.label_lines(k)))]
        assert ", ".join(lines) == anim.frame_labels[k]
        r = path[k]
        if k:  # the numbers of this frame's equilibrium, as the page's overlay states them
            f = float(np.linalg.norm(r.wrench[:3]))
            d = float(np.linalg.norm(r.deflection[:3])) * 1e3
            assert f"|F| = {f:.4g} N" in lines[0] and lines[1] == f"|δ| = {d:.4g} mm"
    # the visible tracks: at each frame time (and half a frame either side of it, not
    # reaching the neighbour's middle), only that frame's text is shown
    sa = next(c for c in cmds if isinstance(c, _SetAnimationAt))
    clips = sa._cmd.animation.clips
    tracks = {}
    for p, clip in clips.items():
        e = tuple(p.entries)
        if len(e) == 4 and e[2] == "text" and "visible" in clip.tracks:
            tracks[int(e[3][1:])] = clip.tracks["visible"]
    assert sorted(tracks) == list(range(n))
    for k in range(n):
        for t in (k, k - 0.4, k + 0.4):
            if 0 <= t <= n - 1:
                shown_now = [j for j in range(n) if _visible_at(tracks[j], t)]
                assert shown_now == [k], (t, shown_now)


def test_exported_page_has_no_scene_text_by_default():
    from vjm_pin.model.registry import resolve_model
    from vjm_pin.viz.viewer import Animation, chain_geometry

    vm = resolve_model("paper-c-s")
    anim = Animation(vm.model, chain_geometry(vm.model, vm.roles), [vm.reference])
    assert not any(
        "text" in tuple(getattr(getattr(c, "path", None), "entries", ())) for c in anim.commands()
    )
