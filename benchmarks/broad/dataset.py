"""BROAD as its authors publish it: a folder with ``trials.json`` (every
trial's description and groups) and the trials as ``data_mat/NN_name.mat``,
``data_hdf5/NN_name.hdf5`` (``h5py``, the ``hdf5`` extra) or, as the toolkit
ships two of them, ``NN_name.npz`` (:func:`sensors.recording.load_recording`'s
keys). Where the folder comes from: ``--broad DIR``, else the environment
variable :data:`ENVIRONMENT_VARIABLE`, else the shipped subset
``datasets/broad/`` (trials 02 and 07).

Everything read is checked where it is read, and a folder that breaks a
rule is one line naming the file, the value and the rule: ``trials.json``
must be BROAD's index (:func:`open_broad`), a trial must be a readable
file with the published keys, finite readings within their sensors'
ranges (:func:`sensors.recording.checked_recording`) and a rest the
estimators can be configured and started from
(:func:`benchmarks.broad.inputs.runnable_rule`); the trials asked for must
be named once each, and at least one of them must have something to score
(:meth:`BroadDataset.selected`).
"""
from __future__ import annotations

import functools
import json
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from benchmarks.broad.inputs import runnable_rule
from benchmarks.broad.trial_notes import (from_start, magnetometer_timed, note_clipping,
                                          note_dropouts, note_silences)
from benchmarks.broad.metric import recording_unscored
from benchmarks.shipped import shipped_file
from dynamics.validation import InvalidParameterError
from sensors.clocks import GAP_FACTOR
from sensors.declared import data_files, load_parts, read_declaration
from sensors.delay import checked_delay
from sensors.recording import Recording, checked_recording, load_recording

ENVIRONMENT_VARIABLE = "ATTITUDE_BENCH_BROAD"
ATTRIBUTION = ("Data: BROAD, D. Laidig, M. Caruso, A. Cereatti, T. Seel, \"BROAD - A "
               "Benchmark for Robust Inertial Orientation Estimation\", Data 6(7), 2021, "
               "doi:10.3390/data6070072; CC BY 4.0.")
#: BROAD's DOI: a folder whose README or LICENSE names it holds BROAD's data.
BROAD_DOI = "10.3390/data6070072"
#: The files a dataset folder's attribution is read from (every one present).
ATTRIBUTION_FILES = ("ATTRIBUTION.txt", "README.md", "README.txt", "README", "LICENSE",
                     "LICENSE.txt", "LICENSE.md")
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
    parameter: str = "broad"     # the flag that gave the folder, for errors
    #: how late each trial's magnetometer reads against its gyro: s, or
    #: "auto" to fit it (:func:`~benchmarks.broad.trial_notes.magnetometer_timed`)
    magnetometer_delay: object = 0.0
    #: trial → whether it has a magnetometer, found once (:meth:`sensors`)
    _fields: dict = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "magnetometer_delay", checked_delay(self.magnetometer_delay))

    @functools.cached_property
    def attribution(self) -> str:
        """Whose data this is, for the ``ATTRIBUTION.txt`` beside every
        output derived from it (:func:`dataset_attribution`), read once."""
        return dataset_attribution(self.folder)

    @property
    def title(self) -> str:
        """The name figures give the data: BROAD where the attribution is
        BROAD's, else the folder's own name."""
        return "BROAD" if self.attribution == ATTRIBUTION else self.folder.resolve().name

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
                                    f"{', '.join(trial_label(n) for n in self.available)})")

    def sensors(self, trials) -> frozenset:
        """The vector sensors ``trials`` read: the accelerometer, and the
        magnetometer unless they have none (a 6-axis IMU's declaration or
        ``.npz``; a published trial holds every channel, and a trial without
        an accelerometer is refused). Trials with and without one are
        refused together: the ones are scored on their total error, the
        others on their inclination, which no mean may mix."""
        for trial in trials:
            if trial not in self._fields:
                self._fields[trial] = self.files[trial].suffix not in (".toml", ".npz") or \
                    self.load(trial).magnetometer_uT is not None
        without = [trial for trial in trials if not self._fields[trial]]
        if without and len(without) < len(trials):
            raise InvalidParameterError(
                "trials" if self.parameter == "broad" else self.parameter,
                ",".join(trial_label(t) for t in trials), f"mix logs without a magnetometer "
                f"({', '.join(without[:3])}{', …' if len(without) > 3 else ''}), scored on "
                "their inclination, with logs that have one, scored on their total error: "
                "run them apart (--trials, or a folder each)")
        return frozenset({"accelerometer"} if without else {"accelerometer", "magnetometer"})

    def selected(self, names=None) -> list[str]:
        """The trials ``names`` (numbers or full names, :meth:`trial_name`;
        None or empty: every trial present), each loaded once to check it
        (:meth:`load`), before any is run.

        Refused, in one line: a trial named twice (``02,2``: it would count
        twice in every mean, and a tuning would score it on settings tuned on
        itself), any trial :meth:`load` refuses, and a selection with nothing
        to score (every trial :func:`~benchmarks.broad.metric.unscored_reason`
        names) unless no trial has a reference at all: those are ranked by
        the estimators' agreement (:mod:`benchmarks.broad.agreement`). A
        trial with nothing to score beside others that have is run, and left
        out of the group means by name
        (:func:`benchmarks.broad.benchmark.group_means`)."""
        if not names:
            trials = self.available
        else:
            trials, given = [], {}
            for text in names:
                name = self.trial_name(str(text).strip())
                if name in given:
                    raise InvalidParameterError(
                        "trials", text, f"names trial {name} a second time (first as "
                        f"{given[name]!r}); each trial may be named once")
                given[name] = text
                trials.append(name)
        reasons = {name: self.unscored(name) for name in trials}
        if all(reasons.values()) and \
                any(self.load(name).has_reference.any() for name in trials):
            raise InvalidParameterError(
                "trials", ",".join(trial_label(name) for name in trials),
                "nothing to score: " + "; ".join(f"{name} {why}" for name, why in
                                                 reasons.items()))
        return trials

    def unscored(self, name: str) -> str | None:
        """Why trial ``name`` has nothing to score, loaded (None: it has)."""
        return recording_unscored(self.load(name))

    def members(self, group: str) -> list[str]:
        """The trials present that belong to ``group``."""
        return [name for name in self.available if group in self.trials[name]["groups"]]

    def load(self, name: str) -> Recording:
        """Trial ``name`` as a checked recording with its accelerometer (and
        its magnetometer, where it has one: a 6-axis IMU's heading is its
        gyro's, :func:`~benchmarks.broad.inputs.heading_reference`), from the
        sample the estimators can be started at
        (:func:`~benchmarks.broad.inputs.runnable_rule`,
        :func:`~benchmarks.broad.trial_notes.from_start`), its magnetometer's
        readings at their samples' times (:attr:`magnetometer_delay`); notes
        (warnings) say how many readings are dropouts (exactly zero, left
        out) and how many samples come before the start (the delay is said
        once a run's inputs are checked: :func:`~benchmarks.broad.
        trial_notes.note_magnetometer_delay`)."""
        path = self.files[name]
        # The file as the folder holds it: a long path would be cut short in
        # the message, and the trial's name with it.
        shown = str(path.relative_to(self.folder))

        def refuse(rule: str):
            raise InvalidParameterError("trial" if self.parameter == "broad"
                                        else f"{self.parameter} trial", shown, rule)
        if path.suffix == ".toml":
            recording = next((part for part in declared_parts(path) if part.name == name), None)
            if recording is None:
                refuse(f"no longer holds part {name} (the file changed since it was listed)")
        elif path.suffix == ".npz":
            try:
                recording = load_recording(path, name)
            except InvalidParameterError as err:
                refuse(err.rule)
        else:
            arrays = (_read_hdf5 if path.suffix == ".hdf5" else _read_mat)(path, refuse)
            missing = [key for key in PUBLISHED_KEYS if key not in arrays]
            if missing:
                refuse(f"has no key {missing[0]!r}; a BROAD trial holds "
                       f"{', '.join(PUBLISHED_KEYS)}")
            data = {PUBLISHED_KEYS[key]: np.asarray(value) for key, value in arrays.items()
                    if key in PUBLISHED_KEYS}
            # MATLAB stores a vector as an (N, 1) matrix and a number as (1, 1);
            # any other shape is left for checked_recording to name.
            data["movement"] = _column(data["movement"])
            if data["sampling_rate_hz"].size == 1:
                data["sampling_rate_hz"] = data["sampling_rate_hz"].reshape(())
            info = np.asarray(arrays.get("info", ())).reshape(-1)
            if info.size and info.dtype.kind in "USO":
                data["info"] = np.asarray(str(info[0]))
            recording = checked_recording(data, name, refuse)
        if recording.accelerometer_mps2 is None:
            refuse("has no imu_acc channel; the IMU filters scored here need the "
                   "accelerometer at least (the gyro alone: attitude-bench replay)")
        rule = runnable_rule(recording)
        if rule:
            refuse(rule)
        if path.suffix != ".toml":       # there, a sensor on its own clock reads at some samples
            note_dropouts(recording, path)
        note_clipping(recording, path)
        recording = from_start(recording, path, refuse)
        note_silences(recording, path)
        return magnetometer_timed(recording, self.magnetometer_delay, path)


def refuse_field_flag(flag: str, value, present) -> None:
    """A magnetometer's setting ``flag`` (given as ``value``) refused where
    the trials' vector sensors ``present`` (:meth:`BroadDataset.sensors`)
    have no magnetometer."""
    if "magnetometer" not in present:
        raise InvalidParameterError(flag, value, "needs a magnetometer, and these trials have none")


def broad_folder(given: Path | None = None) -> Path:
    """``--broad DIR``, else :data:`ENVIRONMENT_VARIABLE`, else the shipped subset."""
    if given is not None:
        return Path(given)
    if os.environ.get(ENVIRONMENT_VARIABLE):
        return Path(os.environ[ENVIRONMENT_VARIABLE])
    return shipped_file("datasets/broad/trials.json").parent


def trial_label(name: str) -> str:
    """A trial as the tables show it: BROAD's number (``02`` for
    ``02_undisturbed_slow_rotation_B``), where the name is one of BROAD's
    published trials; any other name whole (``my_phone_log``, ``01_walk``)."""
    number, _, _ = name.partition("_")
    return number if name in broad_trial_names() else name


@functools.cache
def broad_trial_names() -> frozenset:
    """The names of BROAD's published trials (its ``trials.json``, shipped)."""
    index = json.loads(shipped_file("datasets/broad/trials.json").read_text())
    return frozenset(index["trials"])


def dataset_attribution(folder: Path) -> str:
    """Whose data the folder holds, in one paragraph: its own
    ``ATTRIBUTION.txt`` where it has one; BROAD's citation where its README
    or LICENSE names BROAD's DOI and its trials are BROAD's published ones;
    else the title of its README and the first line of its LICENSE, as they
    are — never another dataset's credit."""
    found = {name: folder / name for name in ATTRIBUTION_FILES if (folder / name).is_file()}

    def text(name: str) -> str:
        try:
            return found[name].read_text(errors="replace")
        except OSError:
            return ""
    if "ATTRIBUTION.txt" in found and text("ATTRIBUTION.txt").strip():
        return text("ATTRIBUTION.txt").strip()
    if any(BROAD_DOI in text(name) for name in found) and _holds_broad_trials(folder):
        return ATTRIBUTION
    firsts = [(name, next((line.strip("# ").strip() for line in text(name).splitlines()
                           if line.strip()), "")) for name in found]
    said = "; ".join(f"{name}: {first}" for name, first in firsts if first)
    # A relative "." has no name: the folder's own, resolved, is what the reader knows.
    shown = folder.name or folder.resolve().name or str(folder.resolve())
    if not said:
        return (f"Data: the recordings in {shown}; the folder has no README or LICENSE "
                "saying whose they are or on what terms (its owner's).")
    return f"Data: the recordings in {shown} ({said}); see those files for their terms."


def _holds_broad_trials(folder: Path) -> bool:
    """Whether the folder's ``trials.json`` names BROAD's published trials only."""
    try:
        named = json.loads((folder / "trials.json").read_text()).get("trials", {})
    except (OSError, ValueError, AttributeError):
        return False
    return bool(named) and set(named) <= broad_trial_names()


def open_broad(folder, parameter: str = "broad") -> BroadDataset:
    """The BROAD folder ``folder``, checked: its ``trials.json`` read
    (:func:`read_index`), its trials found (:data:`LAYOUTS`); an error names
    ``parameter`` (the flag that gave the folder)."""
    folder = Path(folder)

    def refuse(rule: str):
        raise InvalidParameterError(parameter, str(folder), rule)
    if folder.suffix == ".toml" and folder.is_file():
        return declared_dataset([folder], folder.parent, parameter)
    if not folder.is_dir():
        refuse("is not a folder, nor a [recording] .toml file")
    index = folder / "trials.json"
    if not index.is_file():
        declared = sorted(folder.glob("*.toml"))
        if declared:
            _note_undeclared(folder, declared)
            return declared_dataset(declared, folder, parameter)
        refuse("has no trials.json (the dataset's index of trials and groups) and no "
               "[recording] .toml files")
    groups, trials = read_index(index, refuse)
    for sub, suffix in LAYOUTS:
        files = {path.stem: path for path in sorted((folder / sub).glob(f"*{suffix}"))
                 if path.stem in trials}
        if files:
            return BroadDataset(folder=folder, groups=groups, trials=trials, files=files,
                                parameter=parameter)
    refuse("holds none of the trials its trials.json names (looked in data_mat/*.mat, "
           "data_hdf5/*.hdf5 and *.npz)")


def _note_undeclared(folder: Path, declared) -> None:
    """A note naming the .npz recordings beside ``declared`` [recording]
    files that none of them reads: without a trials.json, only the
    declarations are run."""
    read = {file.resolve() for path in declared
            for file in data_files(path, read_declaration(path))}
    left = [path.name for path in sorted(folder.glob("*.npz")) if path.resolve() not in read]
    if left:
        warnings.warn(f"{folder}: left out {', '.join(left)}: without a trials.json a folder's "
                      "[recording] .toml files are its trials (declare one with "
                      f"file = \"{left[0]}\", or move it)", stacklevel=3)


#: The one group of a dataset of declared recordings.
RECORDINGS_GROUP = Group("recordings", 1, "your recordings")


def declared_dataset(paths, folder: Path, parameter: str) -> BroadDataset:
    """A dataset of ``[recording]`` files (:mod:`sensors.declared`), a trial
    for each unbroken part of each (named by its file, and its part where
    the gyro's clock has gaps: :func:`sensors.declared.load_parts`), all in
    one group; a part too short to run is left out, and a note says so."""
    files, left_out = {}, []
    for path in paths:
        parts = declared_parts(path)
        if len(parts) > 1:
            warnings.warn(f"{path.name}: the gyro's clock stops {len(parts) - 1} time(s) (an "
                          f"interval of more than {GAP_FACTOR:g} typical ones): each unbroken "
                          "stretch is a trial of its own, started anew: " + ", ".join(
                              f"{part.name} ({part.n_samples / part.rate_hz:.1f} s)"
                              for part in parts), stacklevel=2)
        for part in parts:
            if part.accelerometer_mps2 is None:
                raise InvalidParameterError(
                    parameter, str(path), "declares no [recording.accelerometer]; the IMU "
                    "filters scored here need it at least (the gyro alone: attitude-bench "
                    "replay --dataset)")
            rule = runnable_rule(part)
            if rule:
                left_out.append((path, part.name, rule))
            else:
                files[part.name] = path
    if not files and len(left_out) == 1:      # the one recording given: its own rule
        raise InvalidParameterError(parameter, str(left_out[0][0]), left_out[0][2])
    if not files:
        raise InvalidParameterError(parameter, str(folder), "holds no recording long enough to "
                                    "run (each part of each [recording] file was left out)")
    for path, part, rule in left_out:
        warnings.warn(f"{path.name}: part {part} left out: {rule}", stacklevel=2)
    trials = {name: {"description": f"declared by {path.name}",
                     "groups": [RECORDINGS_GROUP.name]} for name, path in files.items()}
    return BroadDataset(folder=folder, groups=(RECORDINGS_GROUP,), trials=trials, files=files,
                        parameter=parameter)


def declared_parts(path: Path) -> tuple:
    """The parts of the ``[recording]`` at ``path``, read once while the
    file is unchanged (the dataset lists them, then loads each)."""
    data = data_files(path, read_declaration(path))
    return _declared_parts(path, path.stat().st_mtime_ns,
                           tuple(file.stat().st_mtime_ns for file in data))


@functools.lru_cache(maxsize=16)
def _declared_parts(path: Path, _modified_ns: int, _data_modified_ns: tuple) -> tuple:
    return tuple(load_parts(path))


#: What ``trials.json`` must hold, in words (the published index's layout).
INDEX_LAYOUT = ('{"groups": [{"name": text, "level": whole number, "category": text}, ...], '
                '"trials": {name: {"description": text, "groups": [group names]}, ...}}')


def read_index(index: Path, refuse) -> tuple[tuple, dict]:
    """``trials.json``'s groups (:class:`Group`, in its order) and trials
    (name → description and groups), each field checked: every trial's
    groups a list of group names the index declares. ``refuse(rule)``
    raises the error that names the folder."""
    try:
        described = json.loads(index.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as err:
        refuse(f"trials.json cannot be read as JSON ({type(err).__name__}: {err})")

    def wrong(what: str, value, rule: str):
        shown = repr(value) if len(repr(value)) <= 60 else repr(value)[:57] + "..."
        refuse(f"trials.json: {what} = {shown}: {rule}")
    if not isinstance(described, dict):
        refuse(f"trials.json is not BROAD's index, {INDEX_LAYOUT}")
    declared, groups = set(), []
    if not isinstance(described.get("groups"), list):
        wrong("groups", described.get("groups"), "must be a list of groups")
    for group in described["groups"]:
        if not isinstance(group, dict):
            wrong("a group", group, "must be an object with a name and a level")
        name, level = group.get("name"), group.get("level")
        category = group.get("category", "")
        if not isinstance(name, str) or not name:
            wrong("a group's name", name, "must be text")
        if name in declared:
            wrong("a group's name", name, "must be declared once")
        if isinstance(level, bool) or not isinstance(level, int):
            wrong(f"group {name}'s level", level, "must be a whole number")
        if not isinstance(category, str):
            wrong(f"group {name}'s category", category, "must be text")
        declared.add(name)
        groups.append(Group(name, level, category))
    if not isinstance(described.get("trials"), dict):
        wrong("trials", described.get("trials"), "must be an object of trials by name")
    trials = {}
    for name, trial in described["trials"].items():
        if not isinstance(trial, dict):
            wrong(f"trial {name}", trial, "must be an object with its groups")
        description, members = trial.get("description", ""), trial.get("groups")
        if not isinstance(description, str):
            wrong(f"trial {name}'s description", description, "must be text")
        if not isinstance(members, list) or not all(isinstance(g, str) for g in members):
            wrong(f"trial {name}'s groups", members, "must be a list of group names")
        unknown = [g for g in members if g not in declared]
        if unknown:
            wrong(f"trial {name}'s group", unknown[0], "must be one of the groups the index "
                  "declares")
        if len(set(members)) != len(members):
            wrong(f"trial {name}'s groups", members, "must name each group once")
        trials[name] = {"description": description, "groups": list(members)}
    return tuple(groups), trials


def _column(array: np.ndarray) -> np.ndarray:
    """An ``(N, 1)`` or ``(1, N)`` matrix as ``(N,)``; any other shape as it is."""
    return array.reshape(-1) if array.ndim == 2 and 1 in array.shape else array


def _read_mat(path: Path, refuse) -> dict:
    """A MATLAB trial's arrays; ``refuse(rule)`` names the file."""
    from scipy.io import loadmat
    if path.is_file() and path.stat().st_size == 0:
        refuse("is empty; a BROAD trial is a MATLAB file with the published keys")
    try:
        arrays = loadmat(path)
    except Exception as err:  # noqa: BLE001 - scipy's reader raises many types on a damaged file
        refuse(f"cannot be read as a MATLAB file ({type(err).__name__}: {err})")
    return {key: value for key, value in arrays.items() if not key.startswith("__")}


def _read_hdf5(path: Path, refuse) -> dict:
    """An HDF5 trial's datasets; ``refuse(rule)`` names the file."""
    try:
        import h5py
    except ImportError:
        refuse("is HDF5, which needs h5py: pip install 'attitude-bench[hdf5]'")
    try:
        with h5py.File(path, "r") as file:
            return {key: (file[key].asstr()[()] if file[key].dtype.kind in "OS" else file[key][()])
                    for key in file.keys() if isinstance(file[key], h5py.Dataset)}
    except Exception as err:  # noqa: BLE001 - h5py raises many types on a damaged file
        refuse(f"cannot be read as HDF5 ({type(err).__name__}: {err})")
