"""Per-solver setup of long chains (issue 14: the k = 8 column's critical force): the solver's
construction against the expressions it replaced (bit for bit), the support masks a new
Kinematics copies, and the content key of the chain kernel's layouts (hashed from a sample,
equal only when every byte is)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from tests.chains import random_vjm
from vjm_pin.kinematics.chain import Kinematics
from vjm_pin.kinematics.screw import support_mask
from vjm_pin.model.format import load_vjm
from vjm_pin.model.paper_models import PAPER_BEAM, paper_model_urdf
from vjm_pin.solver import EquilibriumSolver, chain_kernel


def _models():
    return [
        load_vjm(paper_model_urdf("c", "s", beam=PAPER_BEAM, subdivide=8)),
        load_vjm(paper_model_urdf("c", "z", beam=PAPER_BEAM, subdivide=2)),
        *(random_vjm(seed, n_joints=7) for seed in range(4)),  # prismatic joints among them
    ]


def test_solver_construction_matches_the_previous_expressions():
    """length_scale, var_scale, kscale and the triangular mask of a new solver are bit for bit
    those of the expressions the constructor used before (a separate forward kinematics and one
    binding call per joint; |K_θ| as a temporary; np.triu), on the k = 8 column and random chains
    with prismatic joints; the mask is each solver's own array."""
    seen_prismatic = False
    for vm in _models():
        s = EquilibriumSolver(vm)
        data = vm.model.createData()
        pin.forwardKinematics(vm.model, data, vm.reference)
        pts = np.array([m.translation for m in data.oMi[1:]] + [s.p0])
        ls = max(float(np.sqrt(((pts - s.p0) ** 2).sum(axis=1)).max()), 1e-3)
        prism = np.array(
            [vm.model.joints[i + 1].shortname().startswith("JointModelP") for i in range(vm.model.nv)]
        )
        seen_prismatic |= bool(prism.any())
        assert s.length_scale == ls  # the same float, not merely close
        assert np.array_equal(s.var_scale, np.where(prism[s.free], ls, 1.0))
        assert s.kscale == float(np.abs(vm.K_theta).max())
        m = len(s.task)
        assert s._triu.shape == (m, m) and np.array_equal(s._triu, np.triu(np.ones((m, m))))
        other = EquilibriumSolver(vm)
        assert other._triu is not s._triu and s._triu.flags.writeable
        other._triu[0, 0] = 7.0  # one solver's scratch never reaches another's
        assert EquilibriumSolver(vm)._triu[0, 0] == 1.0
    assert seen_prismatic


def test_support_masks_are_each_kinematics_own_copy():
    """Kinematics.support_mask: equal to screw.support_mask for the columns; kept per object; a new
    Kinematics of an equal model gets its own writeable array (no shared state to corrupt)."""
    vm = _models()[0]
    cols = EquilibriumSolver(vm).free
    a, b = Kinematics(vm.model, vm.frame_id), Kinematics(vm.model, vm.frame_id)
    ma, mb = a.support_mask(cols), b.support_mask(cols)
    ref = support_mask(vm.model.nv, cols)
    assert np.array_equal(ma, ref) and np.array_equal(mb, ref)
    assert a.support_mask(cols) is ma and ma is not mb and ma.flags.writeable
    ma[0, :] = ~ma[0, :]
    assert np.array_equal(Kinematics(vm.model, vm.frame_id).support_mask(cols), ref)
    assert np.array_equal(mb, ref)
    rev = cols[::-1].copy()
    assert np.array_equal(Kinematics(vm.model, vm.frame_id).support_mask(rev), support_mask(vm.model.nv, rev))
    assert np.array_equal(Kinematics(vm.model, vm.frame_id).support_mask(None), support_mask(vm.model.nv))


def test_layout_keys_are_equal_only_when_every_byte_is(monkeypatch):
    """Two K_θ that differ in one byte the key's hash does not sample: the keys hash alike but are
    not equal, and the chain kernel builds a layout for each (each equal to one built from
    scratch); an equal copy finds the first one."""
    pytest.importorskip("numba")
    monkeypatch.setattr(chain_kernel, "_SHARED", {})
    monkeypatch.setattr(chain_kernel, "_LAYOUTS", {})
    vm = _models()[0]
    s = EquilibriumSolver(vm)
    nt, free, mask = s.nt, s.free, s.kin.support_mask(s.free)
    kz = np.array(s._kz)
    st = chain_kernel.KEY_SAMPLE_STEP
    rows, cols = np.nonzero(kz[:nt, :nt])  # the nonzero entries of K_θ ...
    skipped = (rows % st != 0) | (cols % st != 0)  # ... that the hash does not sample
    i = int(np.ravel_multi_index((rows[skipped][5], cols[skipped][5]), (nt, nt)))
    kt = np.ascontiguousarray(kz[:nt, :nt])
    raw = bytearray(kt.tobytes())
    raw[8 * i] ^= 1  # the least significant bit (little endian) of one entry: a relative change ~1e-16
    kz2 = kz.copy()
    kz2[:nt, :nt] = np.frombuffer(bytes(raw), float).reshape(nt, nt)
    assert not np.array_equal(kz, kz2) and np.allclose(kz, kz2, rtol=1e-15, atol=0)
    k1 = chain_kernel._content_key(kz, free, nt, mask)
    k2 = chain_kernel._content_key(kz2, free, nt, mask)
    assert hash(k1) == hash(k2) and k1 != k2
    assert chain_kernel._content_key(kz.copy(), free.copy(), nt, mask.copy()) == k1
    la = chain_kernel._layout(np.zeros(1), kz, free, nt, mask)
    lb = chain_kernel._layout(np.zeros(1), kz2, free, nt, mask)
    assert la is not lb and len(chain_kernel._SHARED) == 2
    assert chain_kernel._layout(np.zeros(1), kz.copy(), free, nt, mask) is la
    fresh = chain_kernel._Layout(kz2, free, nt, mask)
    assert np.array_equal(lb.kp, fresh.kp) and np.array_equal(lb.kd, fresh.kd)
    assert not np.array_equal(la.kd, lb.kd)
    # a signed zero is another bit pattern (the pseudo-inverses could carry it): another key
    kz3 = kz.copy()
    r0, c0 = np.argwhere(kz[:nt, :nt] == 0)[0]
    kz3[r0, c0] = -0.0
    assert chain_kernel._content_key(kz3, free, nt, mask) != k1
    # the cache keeps its own copies: the caller's K_θ edited in place afterwards is another model
    kz4 = kz.copy()
    assert chain_kernel._layout(np.zeros(1), kz4, free, nt, mask) is la
    kz4[rows[0], cols[0]] *= 2.0
    assert chain_kernel._layout(np.zeros(1), kz4, free, nt, mask) is not la
    assert chain_kernel._layout(np.zeros(1), kz.copy(), free, nt, mask) is la
