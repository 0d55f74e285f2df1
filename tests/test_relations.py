"""The relations metric (Kümmerle et al. 2009) on synthetic trajectories with known errors."""
import numpy as np
import pytest

from omninav.geometry.se2 import compose, relative
from omninav.services.slam.relations import RelationsError, interpolate, load_relations, relation_errors, score


def truth_and_relations():
    t = np.arange(0.0, 20.0, 0.5)
    poses = np.column_stack([np.cos(t / 4) * 5, np.sin(t / 3) * 4, np.sin(t / 5) * 2])
    pairs = [(i, i + 1) for i in range(0, 38, 2)] + [(0, 30), (5, 39)]
    rel = np.array([(t[a], t[b], *relative(poses[a], poses[b])) for a, b in pairs])
    return t, poses, rel


def test_a_perfect_estimate_scores_zero_in_any_frame():
    t, poses, rel = truth_and_relations()
    moved = compose(np.array([3.0, -7.0, 2.5]), poses)  # the same trajectory in another frame
    result = score(t, moved, rel)
    assert result["relations"] == len(rel)
    for key in ("trans_abs_mean_m", "trans_abs_std_m", "trans_sq_mean", "rot_abs_mean_deg", "rot_sq_mean"):
        assert result[key] == pytest.approx(0.0, abs=1e-9)


def test_a_translation_scale_error_scores_what_is_computed_by_hand():
    t = np.array([0.0, 1.0, 2.0, 3.0])
    truth = np.column_stack([t, np.zeros(4), np.zeros(4)])
    estimate = truth * [1.1, 0, 0]               # drives 10 % too far
    rel = np.array([(0.0, 1.0, 1.0, 0.0, 0.0), (1.0, 3.0, 2.0, 0.0, 0.0)])  # 1 m and 2 m
    result = score(t, estimate, rel)
    # errors 0.1 m and 0.2 m
    assert result["trans_abs_mean_m"] == pytest.approx(0.15)
    assert result["trans_abs_std_m"] == pytest.approx(0.05)
    assert result["trans_sq_mean"] == pytest.approx((0.01 + 0.04) / 2)
    assert result["rot_abs_mean_deg"] == pytest.approx(0.0)


def test_a_heading_rate_error_scores_what_is_computed_by_hand():
    t = np.array([0.0, 1.0, 2.0])
    estimate = np.column_stack([np.zeros(3), np.zeros(3), 0.12 * t])  # turns on the spot, 20 % fast
    rel = np.array([(0.0, 1.0, 0.0, 0.0, 0.10), (0.0, 2.0, 0.0, 0.0, 0.20)])
    result = score(t, estimate, rel)
    errors_deg = np.degrees([0.02, 0.04])
    assert result["rot_abs_mean_deg"] == pytest.approx(errors_deg.mean())
    assert result["rot_abs_std_deg"] == pytest.approx(errors_deg.std())
    assert result["rot_sq_mean"] == pytest.approx(np.mean(errors_deg ** 2))
    assert result["trans_abs_mean_m"] == pytest.approx(0.0, abs=1e-12)


def test_poses_are_interpolated_between_stamps():
    stamps = np.array([0.0, 1.0, 2.0])
    poses = np.array([[0.0, 0.0, 3.0], [1.0, 2.0, -3.0], [3.0, 2.0, -3.0]])
    at, inside = interpolate(stamps, poses, np.array([0.5, 1.25, 2.0, 2.5, -1.0]))
    assert np.allclose(at[0, :2], [0.5, 1.0])
    # 3.0 to −3.0 rad is a 0.283 rad turn through ±π, not 6 rad back through 0
    assert abs(abs(at[0, 2]) - np.pi) < 1e-9
    assert np.allclose(at[1], [1.5, 2.0, -3.0])
    assert np.allclose(at[2], poses[2]) and np.allclose(at[3], poses[2]) and np.allclose(at[4], poses[0])
    assert list(inside) == [True, True, True, False, False]


def test_relations_between_sparse_poses_use_the_interpolated_ones():
    def pose_at(t):  # driving straight at constant heading: linear interpolation is exact
        return np.array([0.3 * t, -0.1 * t, 0.2])

    stamps = np.arange(0.0, 11.0)
    poses = np.array([pose_at(s) for s in stamps])
    rel = np.array([(1.05, 4.35, *relative(pose_at(1.05), pose_at(4.35)))])
    trans, rot, used = relation_errors(stamps, poses, rel)
    assert used.all() and trans[0] == pytest.approx(0.0, abs=1e-12) and rot[0] == pytest.approx(0.0, abs=1e-12)
    rel[0, 2] += 0.05  # the truth says 5 cm further
    trans, _, _ = relation_errors(stamps, poses, rel)
    assert trans[0] == pytest.approx(0.05)


def test_relations_outside_the_trajectory_are_counted_not_scored():
    t, poses, rel = truth_and_relations()
    rel = np.vstack([rel, [100.0, 101.0, 1.0, 0.0, 0.0]])
    result = score(t, poses, rel)
    assert result["relations"] == len(rel) - 1 and result["relations_outside"] == 1
    with pytest.raises(RelationsError, match="no relation"):
        score(t, poses, rel[-1:])


def test_the_relations_file_format(tmp_path):
    path = tmp_path / "r.relations"
    path.write_text("1134864645.90321 1134864646.32420 0.31293 0.02935 0.00000  0.00000 0.00000 0.24198\n\n")
    rel = load_relations(path)
    assert rel.shape == (1, 5) and rel[0, 4] == pytest.approx(0.24198) and rel[0, 0] == pytest.approx(1134864645.90321)
    path.write_text("1 2 3 4 5 6 7 8\n1 2 3\n")
    with pytest.raises(RelationsError, match="line 2"):
        load_relations(path)
    with pytest.raises(RelationsError, match="no such file"):
        load_relations(tmp_path / "missing")
