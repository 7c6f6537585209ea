"""A recording without a reference (issue 30): the estimators ranked by their
agreement with the others' median attitude, said as such
(benchmarks/broad/agreement.py)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from benchmarks.broad.agreement import (AGREEMENT, agreement_scores, mean_attitudes,
                                        median_attitudes)
from benchmarks.cli import main
from conftest import npz_declaration
from sensors.recording import load_recording

TRIAL = Path(__file__).resolve().parents[1] / "datasets" / "broad" / \
    "02_undisturbed_slow_rotation_B.npz"
SECONDS = 70.0          # 40 s of rest, then the slow rotation
ESTIMATORS = "mekf,usque,madgwick,mahony,triad,dead-reckoning"

DECLARATION = npz_declaration(accelerometer=("acc", "m/s^2"), magnetometer=("mag", "uT"))


def _wxyz(rotation: Rotation) -> np.ndarray:
    return np.roll(rotation.as_quat(), 1, axis=-1)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), spread=st.floats(0.01, 0.5))
def test_the_mean_attitude_is_sign_free_and_turns_with_the_frame(seed, spread):
    # Markley et al. (2007): the chordal mean of q and -q is the same, and
    # turning every member by R turns the mean by R.
    rng = np.random.default_rng(seed)
    centre = Rotation.random(random_state=rng)
    members = centre * Rotation.from_rotvec(rng.normal(scale=spread, size=(5, 3)))
    quaternions = _wxyz(members)[:, None, :]
    flipped = quaternions * rng.choice([-1.0, 1.0], size=(5, 1, 1))
    mean = mean_attitudes(quaternions)[0]
    assert np.allclose(mean_attitudes(flipped)[0], mean, atol=1e-12)
    turn = Rotation.random(random_state=rng)
    turned = mean_attitudes(_wxyz(turn * members)[:, None, :])[0]
    expected = _wxyz(turn * Rotation.from_quat(np.roll(mean, -1)))
    assert min(np.abs(turned - expected).max(), np.abs(turned + expected).max()) < 1e-9
    # ... and it is scipy's Rotation.mean of the same set.
    assert abs(np.dot(mean, _wxyz(members.mean()))) == pytest.approx(1.0, abs=1e-12)


def test_the_median_is_not_pulled_by_one_estimator_far_off():
    # Four estimators at one attitude and one turned 90°: the mean moves
    # towards the odd one by degrees, the median (Weiszfeld) stays.
    rng = np.random.default_rng(4)
    centre = Rotation.random(random_state=rng)
    members = [centre] * 4 + [centre * Rotation.from_euler("x", 90.0, degrees=True)]
    quaternions = np.stack([_wxyz(m)[None, :] for m in members])
    truth = _wxyz(centre)

    def off_deg(q):
        return np.degrees(2 * np.arccos(min(abs(np.dot(q[0], truth)), 1.0)))
    assert off_deg(mean_attitudes(quaternions)) > 5.0
    assert off_deg(median_attitudes(quaternions)) < 1e-3


def test_each_estimator_is_scored_against_the_others_only():
    # Three estimators: two at the same attitude, one turned 3° about z.
    # The odd one is 3° from the others' median; each of the two is 1.5°
    # from the median of the other and the odd one (of two, it is halfway).
    n = 10
    base = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    turned = np.tile(_wxyz(Rotation.from_euler("z", 3.0, degrees=True)), (n, 1))
    scores, _ = agreement_scores({"a": base, "b": base, "odd": turned}, ["a", "b", "odd"])
    assert scores["odd"]["agreement_total_deg"] == pytest.approx(3.0, abs=1e-9)
    assert scores["odd"]["agreement_heading_deg"] == pytest.approx(3.0, abs=1e-9)
    assert scores["odd"]["agreement_inclination_deg"] == pytest.approx(0.0, abs=1e-9)
    assert scores["a"]["agreement_total_deg"] == pytest.approx(1.5, abs=1e-9)
    # Alone, an estimator has no one to agree with: NaN, not 0.
    alone, _ = agreement_scores({"a": base, "dead": turned}, ["a"])
    assert np.isnan(alone["a"]["agreement_total_deg"])
    assert alone["dead"]["agreement_total_deg"] == pytest.approx(3.0, abs=1e-9)


@pytest.fixture(scope="module")
def unreferenced(tmp_path_factory):
    """Trial 02's first SECONDS declared without its reference."""
    recording = load_recording(TRIAL)
    keep = int(SECONDS * recording.rate_hz)
    folder = tmp_path_factory.mktemp("unreferenced")
    np.savez(folder / "log.npz", t=recording.time_s[:keep], gyro=recording.gyro_radps[:keep],
             acc=recording.accelerometer_mps2[:keep], mag=recording.magnetometer_uT[:keep])
    (folder / "log.toml").write_text(DECLARATION)
    return folder / "log.toml"


@pytest.mark.slow      # 5 s
def test_a_recording_without_a_reference_is_ranked_by_agreement_and_says_so(
        unreferenced, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["broad", "--broad", str(unreferenced), "--estimators", ESTIMATORS,
                 "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "No trial has a reference" in printed and "agreement, not accuracy" in printed
    assert "total RMSE (°) against the others' median per group" in printed
    trials = pd.read_csv(out / "broad_trials.csv").set_index("estimator")
    assert np.isfinite(trials.loc[list(ESTIMATORS.split(",")),
                                  list(AGREEMENT)].to_numpy()).all()
    # The scored columns hold the agreement, as the header says.
    assert np.array_equal(trials["total_rmse_deg"], trials["agreement_total_deg"])
    # Agreement tells the tiers apart as the reference does on these 70 s
    # (measured, against the others' median / against the reference, °):
    # USQUE 1.58 / 0.98, the MEKF 1.59 / 0.97, Madgwick 1.33 / 1.31, Mahony
    # 2.87 / 3.11, TRIAD 4.60 / 4.83, dead reckoning 10.2 / 10.8. Within
    # the first tier it cannot order them (the MEKF and USQUE share their
    # models, and each is scored against a median that holds the other).
    agreement = trials["agreement_total_deg"]
    first_tier = agreement[["mekf", "usque", "madgwick"]]
    assert first_tier.max() < agreement["mahony"] < agreement["triad"] < \
        agreement["dead-reckoning"]
    assert first_tier.max() < 2.5
    groups = pd.read_csv(out / "broad_groups.csv")
    assert set(groups["estimator"]) == set(trials.index)
    # Both files say what their RMSE columns were taken against.
    assert (trials["scored_against"] == "others' median").all()
    assert (groups["scored_against"] == "others' median").all()


@pytest.mark.slow
def test_without_a_reference_tuning_and_a_lone_heading_are_refused(unreferenced, tmp_path,
                                                                    capsys):
    out = tmp_path / "out"
    assert main(["broad", "--broad", str(unreferenced), "--estimators", "mekf",
                 "--tune", "all-trials", "--out", str(out), "--quiet"]) == 2
    assert "--tune all-trials scores settings against a reference" in capsys.readouterr().err
    assert main(["broad", "--broad", str(unreferenced), "--estimators", "mekf,dead-reckoning",
                 "--out", str(out), "--quiet"]) == 0     # dead reckoning against the MEKF
    capsys.readouterr()
    assert main(["broad", "--broad", str(unreferenced), "--estimators", "dead-reckoning",
                 "--out", str(tmp_path / "none"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "fewer than two estimators observe the heading" in err
    assert "Traceback" not in err and not (tmp_path / "none").exists()


def test_an_estimator_without_a_heading_is_scored_on_its_inclination_only():
    # As against the reference (VQF 6D): an estimator that observes no
    # heading has its total and heading agreement NaN, its inclination kept.
    n = 10
    base = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    turned = np.tile(_wxyz(Rotation.from_euler("z", 3.0, degrees=True)), (n, 1))
    scores, curves = agreement_scores({"a": base, "b": base, "six": turned}, ["a", "b"],
                                      heading={"a", "b"})
    assert np.isnan(scores["six"]["agreement_total_deg"])
    assert np.isnan(scores["six"]["agreement_heading_deg"])
    assert scores["six"]["agreement_inclination_deg"] == pytest.approx(0.0, abs=1e-9)
    assert np.allclose(curves["six"], 0.0)


@pytest.mark.slow      # 3 s
def test_without_a_reference_tuning_on_the_first_half_is_judged_on_the_second(
        unreferenced, tmp_path, capsys, monkeypatch):
    from benchmarks.broad import tuning
    monkeypatch.setattr(tuning, "MAX_EVALUATIONS", 6)
    out = tmp_path / "out"
    assert main(["broad", "--broad", str(unreferenced), "--estimators", "mekf,madgwick",
                 "--tune", "halves", "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "No trial has a reference" in printed and "no reference read" in printed
    tuned = pd.read_csv(out / "broad_tuning.csv")
    assert list(tuned["estimator"]) == ["mekf"]
    # Judged by the likelihood alone: no RMSE column where there is no reference.
    assert np.isfinite(tuned[["held_out_loss_default", "held_out_loss"]].to_numpy()).all()
    assert not any(column.startswith("held_out_rmse") for column in tuned.columns)
    trials = pd.read_csv(out / "broad_trials.csv").set_index("estimator")
    assert np.isfinite(trials.loc[["mekf", "madgwick"], "agreement_total_deg"]).all()
