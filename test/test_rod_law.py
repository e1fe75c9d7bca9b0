"""Rod rung: the tabulated law between grid pressures where the section's bent-back peak jumps
(the lumen's fold). Synthetic tables keep this fast; the D/20 figures are in docs/models/rod.md
and benchmarks/blocking_force.py."""
import numpy as np
import pytest

from softcath_ros.core.models import make_model
from softcath_ros.core.rod.law import TabulatedLaw
from softcath_ros.core.section_fe.moment import MomentTable

L = 0.017
EI = 9e-6
PS = np.arange(0.0, 35000.0 + 1e-9, 2500.0)


@pytest.fixture(scope="module")
def design():
    from softcath_ros.core.design import load_design

    return load_design("implemented_5mm").with_length(L)


def _fold_law(peaks: dict, ends: dict, rise: float = 25.0) -> TabulatedLaw:
    """Bent back |M| = EI (kappa_free(p) + rise (2 s - s^2)), s = kappa / kappa_pk(p): a peak at
    kappa_pk(p) (-120 1/m unless ``peaks`` says otherwise), the table ending at -150 1/m unless
    ``ends`` says otherwise (NaN beyond: the held section stopped); linear on the positive side
    (kappa_free = 100 1/m at 0.35 bar), as implemented_5mm's D/20 law across the lumen's fold."""
    ks = np.arange(-150.0, 300.0 + 1e-9, 5.0)
    kf = 100.0 * PS / 35000.0
    k_pk = np.array([peaks.get(p, -120.0) for p in PS])
    s = ks[:, None] / k_pk[None, :]
    m = np.where(ks[:, None] < 0, -EI * (kf + rise * (2 * s - s**2)), EI * (ks[:, None] - kf))
    end = np.array([ends.get(p, -150.0) for p in PS])
    m[ks[:, None] < end[None, :] - 1e-9] = np.nan
    return TabulatedLaw(MomentTable(curvatures=ks, pressures=PS, moment=m, stretch=np.ones_like(m), messages=[]),
                        source="fold law")


def _blocked(design, law, pressures):
    from softcath_ros.bench.blocking import bench_contact

    rod = make_model("rod", design, source="closed_form")
    rod.law = law
    return rod.solve(np.asarray(pressures, dtype=float), L, bench_contact(L))


def test_the_bent_back_peak_moves_continuously_where_it_jumps_between_grid_pressures(design):
    """The peak jumps from -120 1/m at 0.30 bar to -45 at 0.325 (whose table ends at -75) and -25 at
    0.35 bar (ends at -50). Read at the same curvature, every pressure between 0.30 and 0.325 bar
    would end at -75 1/m with |M| still rising (no known capacity: the blocked rod refused from
    0.30 bar); read at the same fraction of each column's peak, the peak moves continuously between
    the columns' and the blocked rod ramps to 0.35 bar, its base hinged at that peak."""
    law = _fold_law(peaks={32500.0: -45.0, 35000.0: -25.0}, ends={32500.0: -75.0, 35000.0: -50.0})
    grid = {p: law.at(p).limit_moment_if_peaked() for p in (30000.0, 32500.0, 35000.0)}
    assert [round(k) for _, k in grid.values()] == [-120, -45, -25]      # the columns' own peaks
    ps = np.linspace(30000.0, 35000.0, 41)
    limits = [law.at(p).limit_moment_if_peaked() for p in ps]
    assert all(lim is not None for lim in limits)
    k_lim = np.array([k for _, k in limits])
    m_lim = np.abs([m for m, _ in limits])
    assert np.all(np.diff(k_lim) > 0) and np.max(np.diff(k_lim)) < 7.0   # 95 1/m in 40 steps
    assert np.max(np.abs(np.diff(m_lim))) < 0.02 * m_lim.max()
    for lo, hi in ((30000.0, 32500.0), (32500.0, 35000.0)):
        inside = m_lim[(ps >= lo) & (ps <= hi)]
        ends = sorted(abs(grid[p][0]) for p in (lo, hi))
        assert ends[0] * (1 - 1e-6) <= inside.min() and inside.max() <= ends[1] * (1 + 1e-6)
    # each slice stays within its columns' tables, read at the fraction of their peaks
    sl = law.at(31250.0)
    assert sl.kappa_lo == pytest.approx(-150.0 * sl.peak[1] / -120.0) and sl.kappa_lo < sl.peak[1]

    sols = _blocked(design, law, np.arange(1250.0, 35000.0 + 1e-9, 1250.0))
    assert all(s.converged for s in sols), [s.message for s in sols if not s.converged][:1]
    f = np.array([s.contact_force for s in sols])
    assert np.all(np.isfinite(f)) and f[-1] > f[len(f) // 2] > 0
    end = sols[-1]
    assert end.hinge_moment == pytest.approx(grid[35000.0][0]) and end.hinge_rotation < 0
    assert end.kappa.min() >= grid[35000.0][1] - 1e-9


def test_no_peak_is_invented_where_a_column_has_none(design):
    """The 0.325 bar column ends at -75 1/m with |M| still rising (its peak, at -100 1/m, beyond its
    table): between 0.30 and 0.325 bar the law knows no capacity, so the blocked rod refuses past
    0.30 bar with the reason named, as before."""
    law = _fold_law(peaks={32500.0: -100.0}, ends={32500.0: -75.0})
    assert law.at(32500.0).limit_moment_if_peaked() is None
    assert law.at(31250.0).limit_moment_if_peaked() is None
    assert law.at(30000.0).limit_moment_if_peaked()[1] == pytest.approx(-120.0, abs=1.0)
    sols = _blocked(design, law, [30000.0, 31250.0])
    assert sols[0].converged and not sols[1].converged
    assert "before the section's moment peaks" in sols[1].message
