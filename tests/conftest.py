import ast
import functools
import math
import warnings

import numpy as np
from hypothesis import settings
import pytest

from dynamics.quaternion import quat_from_rotvec, quat_multiply, to_body_frame
from estimators.imu import GYRO_SCALE_DENSITY


@pytest.fixture
def rng():
    """A fixed-seed generator for exact (non-statistical) tests."""
    return np.random.default_rng(20261122)


def random_unit_quaternions(rng, n):
    q = rng.standard_normal((n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


@functools.lru_cache(maxsize=None)
def source_tree(path) -> ast.Module:
    """The parsed source of the project's file ``path``, parsed once per
    process: the layout tests walk every module several times."""
    return ast.parse(path.read_text(), filename=str(path))


def random_sky(seed: int, steps: int):
    """Random attitudes ``(steps, 4)`` and what the vector sensors see
    (:class:`dynamics.environment.References`): random Sun directions, a
    field, and an illumination below full Sun at about a fifth of the steps."""
    from dynamics.environment import References
    rng = np.random.default_rng(seed)
    q = random_unit_quaternions(rng, steps)
    sun = rng.standard_normal((steps, 3))
    sun /= np.linalg.norm(sun, axis=1, keepdims=True)
    illumination = np.where(rng.random(steps) < 0.2, 0.5, 1.0)
    return q, References(magnetic_field_nT=3e4 * rng.standard_normal((steps, 3)),
                         sun_unit=sun, illumination=illumination)


def pytest_report_header(config):
    """Name the versions the suite ran on (CI's log then says what was tested)."""
    from importlib.metadata import PackageNotFoundError, version
    names = ("filterpy", "numpy", "scipy", "numba", "matplotlib", "seaborn", "pandas", "tqdm",
             "sgp4", "ppigrf", "hypothesis", "dask", "ahrs", "vqf", "imufusion", "h5py")
    found = []
    for name in names:
        try:
            found.append(f"{name} {version(name)}")
        except PackageNotFoundError:
            found.append(f"{name} (not installed)")
    return "tested with: " + ", ".join(found)


# Property tests draw their examples from a fixed seed (hypothesis's
# derandomize): a run of the suite is the same run everywhere, as the
# statistical tests' fixed seeds are; an invariant is still checked on the
# 50-odd examples each test asks for, shrunk to the smallest if one fails.
settings.register_profile("fixed-seed", derandomize=True)
settings.load_profile("fixed-seed")


def pytest_sessionstart(session):
    """With parallel workers (``-n``), compile the engine's kernels first, two
    processes at a time (:mod:`benchmarks.engine.warm_up`): each worker would
    otherwise meet the same cold kernels at the same moment and compile them
    side by side. Only the controller does it, before its workers start."""
    config = session.config
    workers = config.getoption("numprocesses", default=None)
    if (hasattr(config, "workerinput") or not isinstance(workers, int) or workers < 2
            or config.getoption("collectonly", default=False)):
        return
    from benchmarks.engine.warm_up import warm_up
    try:
        warm_up()
    except Exception as err:      # the tests then compile, and report, what failed here
        warnings.warn(f"the kernels could not be compiled ahead of the tests: {err!r}")


def npz_declaration(**sensors) -> str:
    """A ``[recording]`` declaration of ``log.npz``: its ``t``, its
    ``gyro`` in rad/s and, for each of ``sensors`` (name = ``(array, unit)``
    or ``(array, unit, extra lines)``), that sensor's section."""
    sections = {"gyro": ("gyro", "rad/s"), **sensors}
    text = '[recording]\nfile = "log.npz"\n'
    for name, (array, unit, *extra) in sections.items():
        text += (f'\n[recording.{name}]\ntime = "t"\ncolumns = "{array}"\nunit = "{unit}"\n'
                 + "".join(f"{line}\n" for line in extra))
    return text


def turning_imu(rate, dt, rng):
    """A body turning at ``rate`` ((N, 3) rad/s, body frame) from the
    identity: its gyro (biased by 0.3, −0.2, 0.1 °/s, noise 1e-3 rad/s from
    ``rng``), its true attitude, and the gravity its accelerometer reads
    (9.81 m/s² up, no noise)."""
    gyro = rate + np.radians([0.3, -0.2, 0.1]) + rng.normal(0, 1e-3, rate.shape)
    q = np.empty((len(rate), 4))
    q[0] = [1.0, 0, 0, 0]
    for k in range(1, len(rate)):
        q[k] = quat_multiply(q[k - 1], quat_from_rotvec(rate[k] * dt))
    acc = np.array([to_body_frame(qk, np.array([0.0, 0.0, 9.81])) for qk in q])
    return gyro, q, acc


def imu_filter_settings(dt: float, **extra) -> dict:
    """The MEKF's or USQUE's keywords for the simulated IMUs of the tests
    (:func:`turning_imu`): its IMU models on, as ``broad`` sets them, and a
    prior on the bias of 0.5 °/s; ``extra`` over them."""
    settings = dict(dt=dt, gyro_noise=1e-6, gyro_bias_random_walk=1e-5,
                    initial_bias_sigma_radps=math.radians(0.5), gravity_model="lowpass",
                    magnetometer_model="heading", rest_updates=True, rate_interpolation="end",
                    gyro_scale_density=GYRO_SCALE_DENSITY)
    return {**settings, **extra}
