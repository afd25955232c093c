"""Continuation between structures with similar modes (`floquet.critical_depths(continuation=True)`,
used by the per-pose chain): the same verified answers as solving each structure from its
seeds, across a change of the chatter branch (robot mode to spindle mode), whatever the order
the structures come in, and when the starts come from dissimilar structures (the winding count
then sends them back to the seeds)."""

from __future__ import annotations

import numpy as np
import pytest

from absorber.coupling import with_absorber
from posedyn.stability import floquet
from test_stability_multiscale import CUT, TABLE, structure

#: The issue-17 pose with its 12-13 Hz robot modes softened by 0.05-1: the lowest branch moves
#: from a robot mode (about 29 Hz chatter, 0.77 mm) to the 5.4 kHz spindle mode (1.52 mm).
PATH = [structure([(d, fn, z, k * f if fn < 100 else k) for d, fn, z, k in TABLE]) for f in np.geomspace(0.05, 1.0, 10)]


@pytest.fixture(scope="module")
def from_seeds():
    return floquet.critical_depths(PATH, CUT, 2000.0, verify=True)


def _same(a, b):
    for p, q in zip(a, b):
        assert q.verified and q.converged
        assert q.depth_m == pytest.approx(p.depth_m, rel=5e-3) and q.chatter_hz == pytest.approx(p.chatter_hz, rel=1e-3)


def test_continuation_gives_the_answers_from_the_seeds_across_a_branch_change(from_seeds):
    hz = [p.chatter_hz for p in from_seeds]
    assert hz[0] < 100 and hz[-1] > 5000  # the branch changes along the path
    _same(from_seeds, floquet.critical_depths(PATH, CUT, 2000.0, verify=True, continuation=True))


def test_the_order_of_the_structures_does_not_matter(from_seeds):
    order = np.random.default_rng(3).permutation(len(PATH))
    shuffled = floquet.critical_depths([PATH[i] for i in order], CUT, 2000.0, verify=True, continuation=True)
    _same([from_seeds[i] for i in order], shuffled)


def test_starts_from_dissimilar_structures_are_caught_by_the_count(from_seeds, monkeypatch):
    """The path forced to the shuffled order and every start taken from the first structure: the
    robot-branch starts miss the spindle branch where it is lower (and vice versa); the count
    sends those back to the seeds, and the answers stay the same."""
    order = np.random.default_rng(3).permutation(len(PATH))
    monkeypatch.setattr(floquet, "modal_path", lambda structures: np.arange(len(structures)))
    monkeypatch.setattr(floquet, "CONTINUATION_STRIDE", len(PATH))
    retried = []
    solve = floquet._solve

    def spy(dyns, *args, **kwargs):
        if kwargs.get("hints") is None and len(args) >= 5 and args[4] is True:
            retried.append(len(dyns))
        return solve(dyns, *args, **kwargs)

    monkeypatch.setattr(floquet, "_solve", spy)
    _same([from_seeds[i] for i in order], floquet.critical_depths([PATH[i] for i in order], CUT, 2000.0, verify=True, continuation=True))
    assert sum(retried) >= 1


#: The path's last five structures with an absorber (5 kg tuned to 29 Hz, zeta 0.07): their
#: answers (5.5-13.9 mm) need 32 sub-steps a radian, one level above the first refined.
ABSORBED = [with_absorber(p, 5.0, 5.0 * (2.0 * np.pi * 29.0) ** 2, 0.07) for p in PATH[5:]]


def test_a_continued_job_still_refining_is_counted_at_its_own_resolution_only(monkeypatch):
    """A continued (hinted) job that has not settled at the first refined level gets its winding
    count at the resolution its answer ends at, not also at the first refined one (which a finer
    answer repeats anyway), and the answers stay those from the seeds. (A job settled there is
    counted there; what that count finds can still take it finer.)"""
    seeded = floquet.critical_depths(ABSORBED, CUT, 2000.0, verify=True)
    counted = []
    verify_count = floquet._verify_count

    def spy(char, *args, **kwargs):
        counted.append((id(char.dyn), char.substeps_per_rad))
        return verify_count(char, *args, **kwargs)

    monkeypatch.setattr(floquet, "_verify_count", spy)
    monkeypatch.setattr(floquet, "modal_path", lambda structures: np.arange(len(structures)))
    continued = floquet.critical_depths(ABSORBED, CUT, 2000.0, verify=True, continuation=True)
    _same(seeded, continued)
    first_refined = 2.0 * floquet.coarsest_substeps(CUT)
    finer = [k for k, p in enumerate(continued) if k > 0 and p.substeps_per_rad > first_refined]  # k = 0: from the seeds (not hinted)
    levels = {k: [lv for ident, lv in counted if ident == id(ABSORBED[k])] for k in finer}
    assert finer and all(continued[k].substeps_per_rad in levels[k] for k in finer)
    assert any(first_refined not in levels[k] for k in finer)
