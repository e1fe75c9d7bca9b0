"""Each term of the section potential (core/section_fe/terms) on its own: its gradient and
Hessian blocks against finite differences of its energy, and the problem as their sum."""
import dataclasses

import numpy as np
import pytest

from softcath_ros.core.design import Device, load_design
from softcath_ros.core.models.section import SectionModel
from softcath_ros.core.section_fe.terms.contact import WallContact
from softcath_ros.core.section_fe.terms.device import DeviceBending
from softcath_ros.core.section_fe.terms.fibre import Fibre
from softcath_ros.core.section_fe.terms.hoop import HoopRings
from softcath_ros.core.section_fe.terms.lumen_fill import LumenFill
from softcath_ros.core.section_fe.terms.pressure_volume import ChannelPressure
from softcath_ros.core.section_fe.terms.ring_bending import RingBending
from softcath_ros.core.section_fe.terms.silicone import SiliconeBody


@pytest.fixture(scope="module")
def problem_and_state():
    d = dataclasses.replace(load_design("implemented_5mm"), device=Device(diameter=1e-3, bending_stiffness=2e-6))
    problem = SectionModel(d, mesh_size=d.outer_diameter / 8, lumen_fill=0.05, ring_bending=True).problem
    rng = np.random.default_rng(3)
    x = problem.initial_state()
    x[:problem.n_u] += 0.003 * rng.standard_normal(problem.n_u)
    x[problem.n_u:problem.n] = [1.05, 0.3, -0.2]
    return problem, problem.consistent_pressures(x), rng


def test_every_kind_of_term_is_listed(problem_and_state):
    problem, _, _ = problem_and_state
    kinds = {type(t) for t in problem.terms}
    # the filled lumen has no wall contact; the empty channel has
    assert kinds == {SiliconeBody, LumenFill, Fibre, HoopRings, RingBending, ChannelPressure, DeviceBending, WallContact}


def _scatter(problem, term, c):
    g = np.bincount(term.dofs.ravel(), weights=c.gradient.ravel(), minlength=problem.n)
    return g


def test_each_term_gradient_and_hessian_match_finite_differences(problem_and_state):
    problem, x, rng = problem_and_state
    p = np.array([0.8])
    eps = 1e-6
    for term in problem.terms:
        c = term.assemble(x, p)
        assert c.energy == pytest.approx(term.energy(x, p), rel=1e-12, abs=1e-14)
        g = _scatter(problem, term, c)
        dofs = np.unique(term.dofs)
        idx = rng.choice(dofs, min(6, len(dofs)), replace=False)
        for i in idx:
            xp, xm = x.copy(), x.copy()
            xp[i] += eps
            xm[i] -= eps
            xp, xm = problem.consistent_pressures(xp), problem.consistent_pressures(xm)
            g_fd = (term.energy(xp, p) - term.energy(xm, p)) / (2 * eps)
            assert g[i] == pytest.approx(g_fd, rel=1e-5, abs=1e-7), (type(term).__name__, i)
            # Hessian column i: blocks that hold i, against the change of the gradient
            h_col = np.zeros(problem.n)
            for b, k in zip(*np.nonzero(term.dofs == i)):
                np.add.at(h_col, term.dofs[b], c.hessian[b][:, k])
            h_fd = (_scatter(problem, term, term.assemble(xp, p)) - _scatter(problem, term, term.assemble(xm, p))) / (2 * eps)
            np.testing.assert_allclose(h_col, h_fd, rtol=1e-4, atol=1e-5 * max(1.0, np.abs(h_fd).max()),
                                       err_msg=type(term).__name__)


def test_the_problem_is_the_sum_of_its_terms(problem_and_state):
    problem, x, _ = problem_and_state
    p = np.array([0.8])
    E, g, _, _ = problem.assemble(x, p)
    assert E == pytest.approx(sum(t.energy(x, p) for t in problem.terms), rel=1e-12)
    g_sum = sum(_scatter(problem, t, t.assemble(x, p)) for t in problem.terms)
    g_sum[problem.pinned] = 0.0
    np.testing.assert_allclose(g, g_sum, rtol=1e-12, atol=1e-12)
