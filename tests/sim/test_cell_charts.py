"""The closed loop's first chart names every control once, and legibly: controls on
one spot share a label (a line each) instead of printing over each other."""
from __future__ import annotations

from eskin_industrial.sim.cell.charts import _near


def test_controls_on_one_spot_share_a_label_and_the_others_keep_their_own() -> None:
    # needless squeezes per hour, held %: three at zero and 99 %, two of the paper's
    # at 40 and 46 per hour (0.07 decades apart), one at 0 and 94.8, one far right
    xs = [0.0, 0.0, 0.0, 39.5, 46.3, 0.0, 470.0]
    ys = [99.0, 99.2, 99.0, 60.8, 60.8, 94.8, 98.0]
    groups = _near(xs, ys)
    assert sorted(sorted(g) for g in groups) == [[0, 1, 2], [3, 4], [5], [6]]
    assert groups[0][0] == 1  # the highest first: the label sits at the top point
    assert sorted(i for g in groups for i in g) == list(range(len(xs)))  # each control once
    # zero and one squeeze an hour are a decade apart on the axis: not one spot
    assert sorted(sorted(g) for g in _near([0.0, 1.0], [99.0, 99.0])) == [[0], [1]]
