"""BROAD as its authors publish it: a folder with ``trials.json`` (every
trial's description and groups) and the trials as ``data_mat/NN_name.mat``,
``data_hdf5/NN_name.hdf5`` (``h5py``, the ``hdf5`` extra) or, as the toolkit
ships two of them, ``NN_name.npz`` (:func:`sensors.recording.load_recording`'s
keys). Where the folder comes from: ``--broad DIR``, else the environment
variable :data:`ENVIRONMENT_VARIABLE`, else the shipped subset
``datasets/broad/`` (trials 02 and 07).
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks.shipped import shipped_file
from dynamics.validation import InvalidParameterError
from sensors.recording import Recording, checked_recording, load_recording

ENVIRONMENT_VARIABLE = "ATTITUDE_BENCH_BROAD"
ATTRIBUTION = ("Data: BROAD, D. Laidig, M. Caruso, A. Cereatti, T. Seel, \"BROAD - A "
               "Benchmark for Robust Inertial Orientation Estimation\", Data 6(7), 2021, "
               "doi:10.3390/data6070072; CC BY 4.0.")
#: The published keys → the toolkit's (:data:`sensors.recording.REQUIRED_KEYS`).
PUBLISHED_KEYS = {"imu_gyr": "imu_gyr_radps", "imu_acc": "imu_acc_mps2",
                  "imu_mag": "imu_mag_uT", "opt_quat": "opt_quat", "movement": "movement",
                  "sampling_rate": "sampling_rate_hz"}
#: Where the trials may lie in a folder, and their suffix: the first found is read.
LAYOUTS = (("data_mat", ".mat"), ("data_hdf5", ".hdf5"), (".", ".npz"))


@dataclass(frozen=True)
class Group:
    name: str
    level: int
    category: str


@dataclass(frozen=True)
class BroadDataset:
    """A BROAD folder: its groups (in ``trials.json``'s order), every trial
    it describes (name → description, groups) and the files present."""

    folder: Path
    groups: tuple
    trials: dict                 # name → {"description": str, "groups": [names]}
    files: dict                  # name → path, the trials present

    @property
    def available(self) -> list[str]:
        """The trials present, in ``trials.json``'s order."""
        return [name for name in self.trials if name in self.files]

    def trial_name(self, text: str) -> str:
        """A trial by its full name or its number (``"02"``, ``"2"``)."""
        if text in self.files:
            return text
        matches = [name for name in self.files if text.isdigit() and
                   name.split("_", 1)[0].lstrip("0") == text.lstrip("0")]
        if len(matches) == 1:
            return matches[0]
        raise InvalidParameterError("trials", text, f"is not a trial of {self.folder} (present: "
                                    f"{', '.join(n.split('_', 1)[0] for n in self.available)})")

    def members(self, group: str) -> list[str]:
        """The trials present that belong to ``group``."""
        return [name for name in self.available if group in self.trials[name]["groups"]]

    def load(self, name: str) -> Recording:
        """Trial ``name`` as a checked recording with its accelerometer and magnetometer."""
        path = self.files[name]
        if path.suffix == ".npz":
            recording = load_recording(path, name)
        else:
            arrays = _read_hdf5(path) if path.suffix == ".hdf5" else _read_mat(path)

            def refuse(rule: str):
                raise InvalidParameterError("trial", str(path), rule)
            missing = [key for key in PUBLISHED_KEYS if key not in arrays]
            if missing:
                refuse(f"has no key {missing[0]!r}; a BROAD trial holds "
                       f"{', '.join(PUBLISHED_KEYS)}")
            data = {PUBLISHED_KEYS[key]: np.asarray(value) for key, value in arrays.items()
                    if key in PUBLISHED_KEYS}
            data["movement"] = data["movement"].reshape(-1)
            data["sampling_rate_hz"] = data["sampling_rate_hz"].reshape(())
            if "info" in arrays:
                data["info"] = np.asarray(str(np.asarray(arrays["info"]).reshape(-1)[0]))
            recording = checked_recording(data, name, refuse)
        if not recording.has_vectors:
            raise InvalidParameterError("trial", str(path), "has no accelerometer or no "
                                        "magnetometer channel (imu_acc, imu_mag)")
        return recording


def broad_folder(given: Path | None = None) -> Path:
    """``--broad DIR``, else :data:`ENVIRONMENT_VARIABLE`, else the shipped subset."""
    if given is not None:
        return Path(given)
    if os.environ.get(ENVIRONMENT_VARIABLE):
        return Path(os.environ[ENVIRONMENT_VARIABLE])
    return shipped_file("datasets/broad/trials.json").parent


def open_broad(folder) -> BroadDataset:
    """The BROAD folder ``folder``, checked: its ``trials.json`` read, its
    trials found (:data:`LAYOUTS`)."""
    folder = Path(folder)

    def refuse(rule: str):
        raise InvalidParameterError("broad", str(folder), rule)
    if not folder.is_dir():
        refuse("is not a folder")
    index = folder / "trials.json"
    if not index.is_file():
        refuse("has no trials.json (the dataset's index of trials and groups)")
    try:
        described = json.loads(index.read_text())
        groups = tuple(Group(g["name"], int(g["level"]), g.get("category", ""))
                       for g in described["groups"])
        trials = {name: {"description": t.get("description", ""), "groups": list(t["groups"])}
                  for name, t in described["trials"].items()}
    except (ValueError, KeyError, TypeError, AttributeError) as err:
        refuse(f"trials.json is not BROAD's index: needs groups [{{name, level}}] and trials "
               f"{{name: {{groups}}}} ({type(err).__name__}: {err})")
    for sub, suffix in LAYOUTS:
        files = {path.stem: path for path in sorted((folder / sub).glob(f"*{suffix}"))
                 if path.stem in trials}
        if files:
            return BroadDataset(folder=folder, groups=groups, trials=trials, files=files)
    refuse("holds none of the trials its trials.json names (looked in data_mat/*.mat, "
           "data_hdf5/*.hdf5 and *.npz)")


def _read_mat(path: Path) -> dict:
    from scipy.io import loadmat
    try:
        return {key: value for key, value in loadmat(path).items() if not key.startswith("__")}
    except (OSError, ValueError, NotImplementedError) as err:
        raise InvalidParameterError("trial", str(path), f"cannot be read as a MATLAB file "
                                    f"({type(err).__name__}: {err})") from None


def _read_hdf5(path: Path) -> dict:
    try:
        import h5py
    except ImportError:
        raise InvalidParameterError("trial", str(path), "is HDF5, which needs h5py: pip "
                                    "install 'attitude-bench[hdf5]'") from None
    try:
        with h5py.File(path, "r") as file:
            return {key: (file[key].asstr()[()] if file[key].dtype.kind in "OS" else file[key][()])
                    for key in file.keys() if isinstance(file[key], h5py.Dataset)}
    except OSError as err:
        raise InvalidParameterError("trial", str(path), f"cannot be read as HDF5 ({err})") from None
