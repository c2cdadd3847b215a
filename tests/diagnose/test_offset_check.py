"""diagnose on a record whose road column reads a constant offset (a sensor zero not at rest).

The offset is found by identify's check (:func:`estimator.identify.record.check_offset`):
the baseline is the declared model on the record as it is, the effect is the
``sensor_offset`` of the road column, and the augmented fit is identify's fit of the record
with the offset removed. Before, diagnose named a ``sensor_offset`` of -0.01 m on ``x2``
(its one-channel screen cannot express a road offset), which explained 71 % of the
structured residual and left the augmented parameters far from the truth.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from estimator.diagnose import diagnose
from estimator.identify import Parameters
from suspid.models import get_model

from ..conftest import TABLE1
from .conftest import make_measurement

#: the road sensor's zero, m above the rest position
ROAD_OFFSET = 0.01


@pytest.mark.slow
def test_road_offset_is_the_effect_named_once() -> None:
    model = get_model("quarter2")
    meas = make_measurement([], noise=0.005)
    meas = replace(meas, road={**meas.road, "r": np.asarray(meas.road["r"]) + ROAD_OFFSET})
    params = Parameters.for_model(model, fix={"m1": TABLE1["m1"], "m2": TABLE1["m2"]})
    out = diagnose(model, meas, params).to_json()
    effect = out["effect"]
    assert effect["name"] == "sensor_offset" and effect["params"]["channel"] == "r"
    assert effect["params"]["offset"] == pytest.approx(ROAD_OFFSET, abs=2e-4)
    # named once: the effect, not a second candidate on a position channel nor identify's
    # offset warning line on top of it
    cands = out["evidence"]["candidates"]
    assert [k for k in cands if "offset" in k] == ["sensor_offset"]
    assert cands["sensor_offset"]["refit"]["params"] == effect["params"]
    assert not any(w.startswith("offset:") or "road column" in w for w in out["warnings"])
    assert "road column r reads +0.00998 m" in out["evidence"]["verdict"]
    assert out["evidence"]["offset"]["values"] == {"r": effect["params"]["offset"]}
    # before: the record as it is, far off; after: the corrected record's fit, at the truth
    assert out["augmented"]["cost"] < 1e-2 * out["baseline"]["cost"]
    for k in ("c1", "k1", "c2", "k2"):
        assert out["augmented"]["params"][k] == pytest.approx(TABLE1[k], rel=0.01)
    assert all(w.startswith("baseline (the record as it is): ") for w in out["warnings"])
