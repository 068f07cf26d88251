"""The compact severity timeline of the run summary."""

import numpy as np
import pytest

from cmsensord.monitor.timeline import SeverityTimeline


@pytest.mark.parametrize("n", [1, 59, 60, 61, 121, 1000, 86_400])
def test_bins_are_the_max_of_equal_spans(n):
    sev = np.round(np.random.default_rng(n).random(n), 1)
    tl = SeverityTimeline(bins=60)
    for k, s in enumerate(sev):
        tl.add(float(k + 1), float(s))
    assert len(tl.bins) <= 60
    ref = [sev[i:i + tl.span].max() for i in range(0, n, tl.span)]
    assert tl.bins == ref


def test_render_names_first_times():
    tl = SeverityTimeline()
    for t, s in [(1, 0.0), (2, 0.0), (3, 0.2), (4, 0.6), (5, 1.0), (6, 0.0)]:
        tl.add(float(t), s)
    assert tl.render() == "|··▂▅█·| 1-6 s; first 0.1 at 3 s, 0.5 at 4 s, 1 at 5 s"
    assert SeverityTimeline().render() == "no decision"
