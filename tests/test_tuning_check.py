"""The check before ``broad --tune`` adopts tuned settings (issue 29): nested
cross-validation on the training trials (:func:`benchmarks.broad.tuning.checked`).

Settings tuned on some trials are kept only where, tuned again on each
inner fold of the training trials, they score better than the defaults on
that fold's other trials, pooled over every training trial; else the
defaults are kept and the table says so.
"""
import numpy as np
import pandas as pd
import pytest
from hypothesis import given, strategies as st

from benchmarks.broad import tuning
from benchmarks.cli import main
from tests.test_broad_hostile import TRIAL_02, TRIAL_07, _arrays

#: Four trials made of the two shipped ones (cut as the hostile tests cut
#: them), each under the name of a trial of the same kind; 01 and 06 are
#: their first 4,500 samples, so no two are the same recording.
FOUR = {"01_undisturbed_slow_rotation_A": (TRIAL_02, True), TRIAL_02: (TRIAL_02, False),
        "06_undisturbed_fast_rotation_A": (TRIAL_07, True), TRIAL_07: (TRIAL_07, False)}


def _four_trials(folder):
    import json
    import shutil
    from tests.test_broad_hostile import SHIPPED
    folder.mkdir()
    shutil.copy(SHIPPED / "trials.json", folder / "trials.json")
    assert set(FOUR) <= set(json.loads((folder / "trials.json").read_text())["trials"])
    for name, (source, shorter) in FOUR.items():
        arrays = _arrays(source)
        if shorter:
            for key in ("imu_gyr_radps", "imu_acc_mps2", "imu_mag_uT", "opt_quat", "movement"):
                arrays[key] = arrays[key][:4500]
        np.savez(folder / f"{name}.npz", **arrays)
    return folder


folds = st.lists(st.tuples(st.floats(0.1, 50), st.floats(0.1, 50), st.integers(1, 20)),
                 min_size=1, max_size=4)


@given(folds)
def test_the_check_keeps_the_tuning_where_the_pooled_inner_folds_gain(inner):
    result = tuning.checked({"values": {"beta": 0.1}}, inner)
    count = sum(n for *_, n in inner)
    default = sum(d * n for d, _, n in inner) / count
    tuned = sum(t * n for _, t, n in inner) / count
    assert result["adopted"] == (tuned < default) == result["check"]["adopted"]
    assert result["check"]["check_loss_default_deg"] == pytest.approx(default, rel=1e-12)
    assert result["check"]["check_loss_deg"] == pytest.approx(tuned, rel=1e-12)
    assert result["values"] == {"beta": 0.1}      # the values found stay in the record
    assert result["check"]["check_verdict"].startswith(
        "tuned settings kept" if result["adopted"] else "defaults kept")


def test_a_fold_that_gains_does_not_outvote_the_trials_of_one_that_loses():
    # Pooled over trials, not averaged over folds: 0.2° gained on one trial,
    # 0.1° lost on each of three.
    assert not tuning.checked({"values": {}}, [(2.0, 1.8, 1), (2.0, 2.1, 3)])["adopted"]
    assert tuning.checked({"values": {}}, [(2.0, 1.5, 1), (2.0, 2.1, 3)])["adopted"]


def test_one_training_trial_cannot_be_checked_and_says_so():
    assert tuning.inner_sets(["only"]) == []
    result = tuning.checked({"values": {"beta": 0.1}}, [])
    assert "adopted" not in result
    assert result["check"]["check_verdict"] == "not checked: one training trial"
    assert tuning.inner_sets(["a", "b", "c"]) == [(["b"], ["a", "c"]), (["a", "c"], ["b"])]


@pytest.mark.slow      # six tunings of Madgwick's β on the authors' grid, cut trials: 5 s
@pytest.mark.parametrize("verdict", ["measured", "defaults kept"])
def test_tuning_all_trials_applies_the_settings_its_check_adopts(tmp_path, capsys, monkeypatch,
                                                                 verdict):
    folder = _four_trials(tmp_path / "broad")
    if verdict == "defaults kept":    # the check as if the tuning had lost 1° on every inner fold
        real = tuning.checked
        monkeypatch.setattr(tuning, "checked", lambda result, inner: real(
            result, [(default, default + 1.0, n) for default, _, n in inner]))
    out = tmp_path / "out"
    assert main(["broad", "--broad", str(folder), "--estimators", "madgwick", "--tune",
                 "all-trials", "--out", str(out), "--quiet"]) == 0
    assert "check_verdict" in capsys.readouterr().out
    table = pd.read_csv(out / "broad_tuning.csv", dtype={"training": str, "scored": str})
    assert len(table) == 2 and set(table["training"]) == {"01,06", "02,07"}
    for _, row in table.iterrows():
        # The defaults' score pooled over the inner folds is their mean over
        # the training trials: the same trials, scored with the same settings.
        assert row["check_loss_default_deg"] == pytest.approx(row["training_loss_default_deg"],
                                                              rel=1e-9)
        assert row["adopted"] == (row["check_loss_deg"] < row["check_loss_default_deg"])
    if verdict == "defaults kept":
        assert not table["adopted"].any()
    tuned = pd.read_csv(out / "broad_trials.csv")
    assert main(["broad", "--broad", str(folder), "--estimators", "madgwick",
                 "--out", str(tmp_path / "default"), "--quiet"]) == 0
    default = pd.read_csv(tmp_path / "default" / "broad_trials.csv")
    for _, row in table.iterrows():
        scored = [name for name in FOUR if name[:2] in row["scored"].split(",")]
        got = tuned.set_index("trial").loc[scored, "total_rmse_deg"].to_numpy()
        untuned = default.set_index("trial").loc[scored, "total_rmse_deg"].to_numpy()
        beta_is_default = row["tuned_beta"] == pytest.approx(0.1, rel=1e-12)
        if row["adopted"] and not beta_is_default:
            assert not np.array_equal(got, untuned)
        if not row["adopted"]:
            np.testing.assert_array_equal(got, untuned)
