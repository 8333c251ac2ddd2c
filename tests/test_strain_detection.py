"""Stance detection by coplanarity [Lin 2003, Sect. 5.2] in the strain experiment: the separation statistics
by hand, and the comparison on a simulated walk."""

from __future__ import annotations

import numpy as np
import pytest

from legkit.experiments.strain import DETECTION_MEASURES, calibration_set, separation, stance_detection
from legkit.strain import CompliantFourBarLeg, LegModel, estimate_body_pose, synthetic_benchtop
from legkit.strain.simulated import simulated_walk


def test_separation_by_hand() -> None:
    scores = np.array([0.1, 0.4, 0.35, 0.8, 0.4])
    tripod = np.array([False, True, False, True, False])
    # Pairs (tripod, other): 0.4 > 0.1, 0.4 > 0.35, 0.4 = 0.4 (half); 0.8 beats all three: 5.5 of 6.
    auc, accuracy, threshold = separation(scores, tripod)
    assert auc == pytest.approx(5.5 / 6.0, abs=1e-15)
    # Threshold 0.35 (tripod when > 0.35): both tripod samples found, 2 of 3 others rejected: (1 + 2/3) / 2.
    assert accuracy == pytest.approx((1.0 + 2.0 / 3.0) / 2.0, abs=1e-15) and threshold == 0.35
    assert separation(np.array([1.0, 2.0]), np.array([False, True]))[:2] == (1.0, 1.0)
    with pytest.raises(ValueError, match="both classes"):
        separation(scores, np.ones(5, dtype=bool))


@pytest.mark.slow
def test_plane_residual_detects_tripod_support_better_than_the_printed_rho() -> None:
    # Measured on a simulated walk at 0.2 m/s (docs/strain.md): the printed rho separates tripod support from
    # more toes down (AUC ~0.94) but depends on the body frame's origin; the plane residual does not (~0.99).
    leg = CompliantFourBarLeg()
    model = LegModel.fit(*calibration_set(synthetic_benchtop(leg, seed=0)), order=1)
    stream = simulated_walk(0.2, 2.0, 0)
    estimate = estimate_body_pose(stream.hip_angle, stream.strain, model, stream.stance_centre, stream.toe_radius)
    rows = {row.measure: row for row in stance_detection(stream, estimate)}
    assert set(rows) == set(DETECTION_MEASURES)
    paper, moved, residual = rows["rho (paper, Sect. 5.2)"], rows["rho, body origin +0.1 m x"], rows["plane residual"]
    assert 0.85 < paper.auc < residual.auc and residual.auc > 0.97
    assert moved.auc < paper.auc - 0.05  # the printed rho changes with the origin of the body frame
    # Large values point out tripod support (the paper's reading) for every measure.
    assert all(row.tripod_median > row.more_toes_median for row in rows.values())
