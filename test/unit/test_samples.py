"""Thinned sample storage (``keep_samples``): the kept samples are exactly the full run's samples
at the kept rows, with every event's samples, the first and the last; the run itself is unchanged."""
import numpy as np
import pytest

import biped_sim as bs
from biped_sim.engine.results import IMPACT_KINDS, Samples


@pytest.fixture(scope="module")
def walk_runs():
    scene = bs.load_scene("walk")
    full = scene.simulate(t_final=1.5)
    thinned = {k: scene.simulate(t_final=1.5, keep_samples=k) for k in (7, "events", 1)}
    return full, thinned


def rows_of(full, part):
    """Indices of ``part``'s samples among ``full``'s (same time and state), in order."""
    idx, i = [], 0
    for t, q in zip(part.t, part.q):
        while not (full.t[i] == t and np.array_equal(full.q[i], q)):
            i += 1
        idx.append(i)
        i += 1
    return idx


@pytest.mark.parametrize("keep", [7, "events", 1])
def test_thinned_samples_are_the_full_runs_samples_with_every_event(walk_runs, keep):
    full, runs = walk_runs
    part = runs[keep]
    assert part.status == full.status == "completed"
    assert [(e.time, e.kind) for e in part.events] == [(e.time, e.kind) for e in full.events]
    np.testing.assert_array_equal(part.q[-1], full.q[-1])
    idx = rows_of(full, part)
    assert idx[0] == 0 and idx[-1] == len(full.t) - 1
    for name in ("dq", "grf", "u", "stance_leg", "energy_balance"):
        np.testing.assert_array_equal(getattr(part, name), getattr(full, name)[idx])
    impacts = [e for e in full.events if e.kind in IMPACT_KINDS]
    assert impacts
    for ev in impacts:       # the samples before and after each impact are both kept
        at = np.flatnonzero(part.t == ev.time)
        assert len(at) == 2 and part.stance_leg[at[0]] == ev.stance_leg_before
        assert part.stance_leg[at[1]] == ev.stance_leg_after
    if keep == 1:
        assert len(part.t) == len(full.t)
    elif keep == 7:
        assert set(range(0, len(full.t), 7)) <= set(idx)
        assert len(part.t) < len(full.t) / 5
    else:
        # the first, the last, one sample at each report (scuff), two at each impact
        assert len(part.t) == 2 + sum(2 if e.kind in IMPACT_KINDS else 1 for e in full.events)
        assert {e.time for e in impacts} <= set(part.t[1:-1])


@pytest.mark.parametrize("bad", [0, -3, 2.5, "every", None])
def test_keep_samples_refuses_what_it_cannot_mean(bad):
    with pytest.raises(ValueError, match="keep_samples"):
        bs.load_scene("walk").simulate(t_final=0.1, keep_samples=bad)


def test_a_sample_row_is_136_bytes():
    s = Samples()
    for k in range(1000):
        s.append(float(k), [0.0] * 5, [0.0] * 5, 1, [0.0, 0.0], [0.0, 0.0], 0.0)
    assert s.rows().shape == (1000, Samples.WIDTH) and s.rows().itemsize * Samples.WIDTH == 136
