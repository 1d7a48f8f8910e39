"""XLA:CPU options: the opt-in small loops (XLA_FLAGS handling, the elementwise inverse they need) and the quick
compile (its fallback); each gives the same solution as XLA's default."""

import json
import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from growjax.simulation import xla_flags
from growjax.simulation.rosenbrock import inverse

OPTION = "xla_cpu_small_while_loop_byte_threshold"


def test_the_option_joins_existing_flags_and_never_overrides_a_users_setting():
    assert xla_flags.with_small_loops("") == f"--xla_backend_extra_options={OPTION}=1000000000"
    assert xla_flags.with_small_loops("--xla_dump_to=/tmp/d") == (
        f"--xla_dump_to=/tmp/d --xla_backend_extra_options={OPTION}=1000000000"
    )
    joined = xla_flags.with_small_loops("--xla_backend_extra_options=a=1")
    assert joined == f"--xla_backend_extra_options=a=1,{OPTION}=1000000000"
    own = f"--xla_backend_extra_options={OPTION}=0"
    assert xla_flags.with_small_loops(own) == own


def test_the_solver_takes_the_option_only_at_a_limit_its_loop_fits_under(monkeypatch):
    monkeypatch.setenv("XLA_FLAGS", f"--xla_backend_extra_options={OPTION}=0")
    assert not xla_flags.applied() and not xla_flags.apply()  # a user's own low limit stays, and is not in force
    monkeypatch.setenv("XLA_FLAGS", xla_flags.with_small_loops(""))
    assert xla_flags.applied()
    monkeypatch.delenv("XLA_FLAGS")
    assert not xla_flags.applied()
    jnp.zeros(1).block_until_ready()  # JAX's backend has started: the option can no longer take effect
    assert not xla_flags.apply() and "XLA_FLAGS" not in os.environ


@pytest.mark.parametrize("n", [1, 6, 9])
def test_elementwise_inverse_matches_lapack_on_stiff_solver_matrices(n):
    """W = I − hγJ with J spanning eight decades of stiffness (the opened bypass is ~1e5 s⁻¹), and a matrix
    whose first pivot is zero (pivoting needed)."""
    rng = np.random.default_rng(n)
    for _ in range(5):
        jac = rng.normal(size=(n, n)) * 10.0 ** rng.uniform(-2, 6, size=(n, 1))
        w = np.eye(n) - 1e-3 * 0.4358665 * jac
        inv = np.asarray(inverse(jnp.asarray(w)))
        assert np.max(np.abs(inv @ w - np.eye(n))) < 1e-9
        np.testing.assert_allclose(inv, np.linalg.inv(w), rtol=1e-9, atol=1e-12 * np.max(np.abs(inv)))
    if n > 1:
        perm = np.roll(np.eye(n), 1, axis=0)  # zero diagonal: fails without row exchanges
        np.testing.assert_allclose(np.asarray(inverse(jnp.asarray(perm))), perm.T, atol=1e-15)


def test_quick_compile_joins_flags_and_falls_back_where_jaxlib_lacks_it(monkeypatch):
    assert (
        xla_flags.quick_compile_flags("--xla_dump_to=/tmp/d")
        == "--xla_dump_to=/tmp/d --xla_cpu_use_fusion_emitters=false"
    )
    own = "--xla_cpu_use_fusion_emitters=true"
    assert xla_flags.quick_compile_flags(own) == own
    lowered = jax.jit(lambda x: 2.0 * x).lower(1.5)
    monkeypatch.setattr(xla_flags, "QUICK_COMPILE", {"xla_cpu_no_such_option": False})
    assert float(xla_flags.compile_quickly(lowered)(1.5)) == 3.0  # an unknown option: XLA's default compile
    monkeypatch.setattr(lowered, "compile", lambda **kw: (_ for _ in ()).throw(RuntimeError("out of memory")))
    with pytest.raises(RuntimeError, match="out of memory"):  # any other failure is not hidden
        xla_flags.compile_quickly(lowered)


def test_a_program_compiles_with_either_emitters_whatever_the_process():
    lowered = jax.jit(lambda x: 2.0 * x).lower(1.5)
    for quick in (True, False):
        assert float(xla_flags.compile_quickly(lowered, quick)(1.5)) == 3.0
        with xla_flags.compiling(quick):
            assert xla_flags.quick_compile_in_force() is quick
    assert xla_flags.quick_compile_in_force() is xla_flags.quick_compile_applied()


def test_quick_compile_for_a_process_leaves_a_users_setting_and_a_started_backend(monkeypatch):
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_use_fusion_emitters=true")
    assert not xla_flags.apply_quick_compile() and os.environ["XLA_FLAGS"] == "--xla_cpu_use_fusion_emitters=true"
    monkeypatch.delenv("XLA_FLAGS")
    jnp.zeros(1).block_until_ready()  # JAX's backend has started: the option can no longer take effect
    assert not xla_flags.apply_quick_compile() and "XLA_FLAGS" not in os.environ


RUN = """
import growjax as gj
cfg = gj.Config(t1=2.0)
inputs = gj.Inputs(catheter_length=gj.Constant(0.02), pressure_demand=gj.published_pulse())
traj = gj.simulate(gj.reference(), inputs, cfg)
# The same compiled solver under a demand beyond the membrane limit: the stop must not depend on the emitters.
over = gj.simulate(gj.reference(), gj.Inputs(catheter_length=gj.Constant(0.02),
                                             pressure_demand=gj.PulseTrain(amplitude=600e3)), cfg)
result = {"length": [float(x) for x in traj.length], "status": int(traj.status),
          "over_status": int(over.status), "limit_time": float(over.limit_time)}
"""
CHILD = (
    """
import json, os, sys
import growjax.simulation.xla_flags as xf
if sys.argv[1] == "quick":
    os.environ["XLA_FLAGS"] = xf.quick_compile_flags("")
applied = xf.apply() if sys.argv[1] == "on" else xf.applied()
"""
    + RUN
    + """
print(json.dumps({"applied": applied, **result}))
"""
)


@pytest.mark.parametrize(
    "modes", [("off",), pytest.param(("on", "off", "quick"), marks=pytest.mark.slow)], ids=["default", "all"]
)
def test_a_simulation_under_each_option_gives_the_same_solution(modes):
    """The same 2 s run in one process per option: XLA's default (which the test run itself does not use,
    conftest.py), and (slow) the quick compile alone and the small loops; and in this process, under the test
    run's own options (quick compile, backend level 0): the same length to within the solver's tolerance (the
    elementwise inverse and other emitters round differently, which can move an adaptive step); and a 600 kPa
    pulse stops at the pressure limit in each, at the same time."""
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    here: dict = {}
    exec(RUN, here)
    out = {"test run": here["result"]}
    for mode in modes:
        run = subprocess.run(
            [sys.executable, "-c", CHILD, mode], capture_output=True, text=True, env=env, timeout=300, check=False
        )
        assert run.returncode == 0, run.stderr[-2000:]
        out[mode] = json.loads(run.stdout.strip().splitlines()[-1])
    assert not out["off"]["applied"] and out.get("on", {"applied": True})["applied"]
    assert all(out[m]["status"] == 0 for m in out)
    off = np.asarray(out["off"]["length"])
    assert np.ptp(off) > 1e-3  # millimetres of growth
    for m in out:
        assert np.max(np.abs(np.asarray(out[m]["length"]) - off)) < 2e-6  # 2 µm
    stops = [out[m]["limit_time"] for m in out]
    assert all(out[m]["over_status"] == 1 for m in out), out  # status 1 (pressure limit), never 2
    assert 0.26 < min(stops) and max(stops) - min(stops) < 1e-4, stops  # after the first rise; 0.1 ms
