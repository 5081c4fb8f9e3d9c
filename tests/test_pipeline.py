from __future__ import annotations

import numpy as np
from tests.helpers.scenes import grasp

from eskin_industrial.calibration import Calibrator
from eskin_industrial.detect import GraspState, paper_batch
from eskin_industrial.frames import RawScan
from eskin_industrial.pipeline import Pipeline


def test_raw_scans_give_the_offline_answer(paper_profile):
    f = grasp(600, seed=9)
    f[:100] = 0.0
    cal = Calibrator.from_section(paper_profile.calibration, 25)
    raw = np.rint(cal.to_raw(f))  # what the node sends: integer 0.1 ohm units
    pipe = Pipeline(paper_profile, method="paper")
    t = np.arange(600) / 100.0
    updates = []
    for k in range(600):
        if k in (300, 301):  # two scans lost on the way
            continue
        updates += pipe.push(RawScan(seq=k, t=t[k], raw=raw[k]))
    assert pipe.counters.lost_scans == 2 and pipe.counters.scans == 598
    keep = np.ones(600, bool)
    keep[[300, 301]] = False
    x, y = paper_profile.coordinates_mm
    forces, _ = cal.to_newtons(raw)
    offline = paper_batch(paper_profile.detector, x, y, 100.0, t[keep], forces[keep])
    assert len(updates) == len(offline)
    np.testing.assert_allclose([u.r_coe for u in updates], offline.r_coe, atol=1e-9)
    np.testing.assert_array_equal([u.state for u in updates], offline.state)
    assert updates[0].state == GraspState.NO_CONTACT and updates[-1].state != GraspState.NO_CONTACT
    assert pipe.last_update is updates[-1]
    changes = 1 + int(np.count_nonzero(np.diff(offline.state)))
    assert pipe.counters.state_changes == changes
