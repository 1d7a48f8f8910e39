"""Shared fixtures. Compiled solvers are cached on disk across test processes (xdist workers, CLI subprocesses)."""

import os
import re
from pathlib import Path

from growjax.simulation import xla_flags

# The run is mostly compiles: XLA's quicker emitters for all of it (growjax.simulation.xla_flags), set before JAX
# starts and inherited by the xdist workers and CLI subprocesses; only for a jaxlib known to have them (XLA aborts a
# process on an unknown flag). test_xla_flags runs XLA's default too.
xla_flags.apply_quick_compile()
# and XLA's backend at optimisation level 0: the suite's compiles about 13 % quicker in all, its longest runs slower;
# rounding moves as under the quick emitters (no assertion here rests on the last bits).
if "xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_backend_optimization_level=0").strip()
# and without XLA's loop-invariant code motion and while-loop simplification, which run to a fixed point on the
# solver's nested loops: a gradient program of the solver compiles in 6 s instead of 14 s, the suite about 11 %
# quicker; rounding moves as above.
if "xla_disable_hlo_passes" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (
        os.environ.get("XLA_FLAGS", "")
        + " --xla_disable_hlo_passes=while-loop-invariant-code-motion,simplify-while-loops"
    )

import jax
import jax.numpy as jnp
import numpy as np
import pytest

jax.config.update("jax_enable_x64", True)
_CACHE = os.environ.setdefault("GROWJAX_CACHE_DIR", str(Path(__file__).resolve().parents[1] / ".jax_cache"))
jax.config.update("jax_compilation_cache_dir", _CACHE)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)

import growjax as gj
from growjax.data import experiment as ex
from growjax.data import sets as xs

REPO = Path(__file__).resolve().parents[1]
DATASETS = REPO / "src" / "growjax" / "data" / "datasets"


def one_experiment(times, length, inputs=None, *, base=None, drive="forward", pressure=None, window=None):
    """The set of one experiment made of arrays: its length (m) (and pressure, Pa) at ``times`` (s), run with
    ``inputs`` (None: made from the columns) on the parameters ``base`` (None: the drive's reference)."""
    experiment = ex.from_arrays(times, length, pressure)
    return xs.ExperimentSet.single(experiment, drive=drive, defaults=base, inputs=inputs, window=window)


def linear_emulator(prior, times):
    """An emulator for the prior ``prior`` of Y at ``times`` (s) whose table is a known length,
    L = 20 mm/s · (1 − (Y − 9 kPa)/20 kPa) · t, linear in Y (so its ghost nodes are exact): NUTS runs in seconds,
    no model solve or compile of the simulator."""
    from growjax.posterior import emulator as em

    spacing = (prior.high - prior.low) / (prior.nodes - 1)
    nodes = prior.low + spacing * np.arange(-1, prior.nodes + 1)  # with one ghost node per side
    values = 2e-2 * (1.0 - (nodes[:, None] - 9000.0) / 20000.0) * times[None, :]
    return em.Emulator(
        values=jnp.asarray(values),
        times=jnp.asarray(times),
        lows=jnp.asarray([prior.low]),
        highs=jnp.asarray([prior.high]),
        error_rms=jnp.asarray(0.0),
        error_max=jnp.asarray(0.0),
        base=gj.reference(),
        inputs=None,
        names=(prior.name,),
        log=(False,),
        nodes=(prior.nodes,),
        config=gj.Config(t1=0.8),
    )


# The test run spreads whole files over its workers (``--dist loadfile``), except the files that fit the published
# pulse over 10 s (Y alone, and Y with the rig's errors): they go to one worker, one after another, so that the later
# ones find those programs compiled in memory instead of compiling them again.
SHARED_PROGRAMS = {
    name: "fits_of_the_published_pulse" for name in ("test_calibration.py", "test_rig.py", "test_uncertainty.py")
}


# The longest scopes first (seconds each took in a cold run on a quiet 2-core CPU, two workers), so that no worker
# is left with a long unit while the other is idle; the rest follow in xdist's order (most tests first). Each
# tutorial executed at its reduced sizes (tests/test_docs.py, in a kernel of its own) is a unit of its own.
LONGEST_FIRST = (
    "fits_of_the_published_pulse",  # 164 s
    "tutorial sets",  # 114 s
    "tutorial fit_posterior",  # 107 s
    "test_sweep.py",  # 80 s
    "test_model.py",  # 70 s
    "tutorial track",  # 68 s
    "test_sets.py",  # 67 s
    "tutorial control",  # 60 s
    "test_design.py",  # 57 s
    "test_discover_set.py",  # 57 s
    "test_discover.py",  # 55 s
    "tutorial discover",  # 41 s
    "test_control.py",  # 41 s
    "test_population.py",
    "test_resampling.py",
    "test_effects.py",
    "test_cli.py",
    "test_inference_data.py",
    "test_track.py",
    "test_fidelity.py",
    "test_xla_flags.py",
    "test_growth_law.py",
    "test_progress.py",
    "docs build",
    "test_track_change.py",
    "test_install.py",
    "test_track_feedback.py",
    "tutorial sweep",
    "test_api.py",
    "tutorial simulate",
    "test_layering.py",
)


def _scope(nodeid: str) -> str:
    """The unit a worker takes whole: a file, the published pulse's fits, or one tutorial or the docs build."""
    file, _, test = nodeid.partition("::")
    tutorial = re.fullmatch(r"test_tutorial_executes_at_reduced_sizes\[(\w+)\]", test)
    if tutorial:
        return f"tutorial {tutorial[1]}"
    if test == "test_docs_build_strict":
        return "docs build"
    return SHARED_PROGRAMS.get(Path(file).name, file)


def pytest_xdist_make_scheduler(config, log):
    if config.getoption("dist") != "loadfile":  # another mode asked for: xdist's own
        return None
    from xdist.scheduler import LoadScopeScheduling

    class FilesSharingPrograms(LoadScopeScheduling):
        def _split_scope(self, nodeid):
            return _scope(nodeid)

        def _assign_work_unit(self, node):
            if not getattr(self, "_longest_first", False):
                rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
                queue = sorted(self.workqueue.items(), key=lambda kv: rank.get(Path(kv[0]).name, len(rank)))
                self.workqueue.clear()
                self.workqueue.update(queue)
                self._longest_first = True
            super()._assign_work_unit(node)

    return FilesSharingPrograms(config, log)


@pytest.fixture(scope="session")
def shared_experiment():
    """The public MAMMOBOT experiment from ../shared/data/mammobot (skipped where absent)."""
    folder = ex.shared_experiment_dir()
    if folder is None:
        pytest.skip("the shared MAMMOBOT experiment (../shared/data/mammobot) is not beside this checkout")
    return ex.read(folder / "experiment.csv")


@pytest.fixture(scope="session")
def synthetic_experiment():
    """The synthetic forward-drive experiment shipped with the package (growjax/data/datasets)."""
    return ex.read(DATASETS / "synthetic_forward.csv")


def forward_inputs(amplitude=150e3, catheter=0.02):
    """Published pulse timing with a chosen amplitude, constant catheter length (m)."""
    t = np.array([0.0, 100.0])
    return gj.Inputs(
        catheter_length=gj.Sampled(t, np.full(2, catheter)),
        pressure_demand=gj.PulseTrain(amplitude=amplitude),
    )


# One configuration for the short physics checks of the fast configuration, so they share one compiled solver.
SHORT = gj.Config(t1=3.0)


def smooth_perturbation(rng, t, size, scale):
    """A smooth random curve on ``t`` (s): a draw of a squared-exponential process of time scale ``scale`` (s),
    scaled to RMS ``size`` (m)."""
    k = np.exp(-0.5 * ((t[:, None] - t[None, :]) / scale) ** 2) + 1e-9 * np.eye(t.size)
    d = np.linalg.cholesky(k) @ rng.standard_normal(t.size)
    return d * size / np.sqrt(np.mean(d**2))


def ar1_noise(rng, t, sd, tau):
    """Correlated sensor noise on a 10 ms grid ``t``: AR(1) of marginal sd ``sd`` (m) and time constant ``tau`` (s)."""
    phi = np.exp(-0.01 / tau)
    x = np.empty(t.size)
    x[0] = rng.normal(0.0, sd)
    for i in range(1, t.size):
        x[i] = phi * x[i - 1] + rng.normal(0.0, sd * np.sqrt(1.0 - phi**2))
    return x


def objective_differences(evaluate, x, step=1e-3):
    """Central differences (k,) of ``evaluate(x) → scalar`` along each coordinate of ``x`` (k,), step ``step``."""
    out = []
    for k in range(np.size(x)):
        e = np.zeros(np.size(x))
        e[k] = step
        out.append((float(evaluate(x + e)) - float(evaluate(x - e))) / (2 * step))
    return out


# ``GROWJAX_TEST_CPU=FILE``: each test's CPU seconds (setup, call and teardown, of the worker's process, its JAX
# threads included) appended to FILE, one "worker nodeid seconds" line each. Unlike wall time, CPU time does not
# grow with the machine's load: the sum over a worker's tests is what that worker needs of one core.
_CPU_LOG = os.environ.get("GROWJAX_TEST_CPU")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    import time

    start = time.process_time()
    yield
    if _CPU_LOG:
        worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
        with open(_CPU_LOG, "a") as log:
            log.write(f"{worker} {item.nodeid} {time.process_time() - start:.2f}\n")
