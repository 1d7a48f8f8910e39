"""Progress output: bars on a terminal, a line every ~10 % on other streams, nothing when quiet; a posterior's
draws the same wherever its progress goes."""

import io
import sys

import numpy as np
from conftest import linear_emulator, one_experiment
from tqdm import tqdm

import growjax as gj
from growjax import posterior as gpost
from growjax import progress as prog
from growjax.calibration import Likelihood


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_a_non_terminal_stream_gets_a_plain_line_every_tenth():
    stream = io.StringIO()
    with prog.bar(200, "sweep", "chunk", stream=stream) as shown:
        for _ in range(200):
            shown.update(1)
    lines = stream.getvalue().splitlines()
    assert "\r" not in stream.getvalue()
    assert [line.split(" (")[0] for line in lines] == [f"sweep: {k}/200 chunks" for k in range(20, 201, 20)]
    assert lines[-1].startswith("sweep: 200/200 chunks (100 %), ") and lines[-1].endswith(" s")
    assert len(stream.getvalue()) < 600  # ten short lines, however many steps


def test_a_stopped_run_ends_with_how_far_it_got_and_few_steps_give_a_line_each():
    stream = io.StringIO()
    shown = prog.bar(40, "fits", "fit", stream=stream)
    for _ in range(9):
        shown.update(1)
    shown.close()
    shown.close()
    assert [line.split(" (")[0] for line in stream.getvalue().splitlines()] == [
        "fits: 4/40 fits",
        "fits: 8/40 fits",
        "fits: 9/40 fits",
    ]
    stream = io.StringIO()
    with prog.bar(3, "x", stream=stream) as shown:
        for _ in range(3):
            shown.update(1)
    assert [line.split(" (")[0] for line in stream.getvalue().splitlines()] == ["x: 1/3", "x: 2/3", "x: 3/3"]


def test_quiet_prints_nothing_and_a_terminal_gets_a_bar():
    stream = io.StringIO()
    with prog.bar(50, "sweep", stream=stream, enabled=False) as shown:
        shown.update(50)
    prog.note("posterior: NUTS", enabled=False, stream=stream)
    assert stream.getvalue() == ""
    prog.note("posterior: NUTS", stream=stream)
    assert stream.getvalue() == "posterior: NUTS\n"
    terminal = _Terminal()
    shown = prog.bar(5, "sweep", "chunk", stream=terminal)
    assert isinstance(shown, tqdm)
    shown.update(5)
    shown.close()
    assert "\r" in terminal.getvalue() and "5/5" in terminal.getvalue()
    assert prog.terminal(terminal) and not prog.terminal(io.StringIO())


def test_posterior_draws_do_not_depend_on_where_progress_goes(monkeypatch):
    """A posterior (2 chains through a linear emulator) drawn with its phases in a log, and with NumPyro's bars on a
    terminal: a line per phase in the log, bars only on the terminal, the same draws. NumPyro steps its bars' loop
    from Python and compiles the quiet one whole, so the two round apart by a few units in the last place (a log's
    draws and a quiet run's are the same loop, equal bit for bit)."""
    for name in ("CI", "PYTEST_XDIST_WORKER"):  # NumPyro turns its bars off under these
        monkeypatch.delenv(name, raising=False)
    prior = gpost.paper_priors()[0]
    times = np.arange(0.01, 0.81, 0.01)  # s
    length = 2e-2 * times + np.random.default_rng(0).normal(0.0, 2e-4, times.size)
    kw = dict(config=gj.Config(t1=0.8), priors=[prior], chains=2, warmup=30, samples=30, seed=1, progress=True)
    kw.update(emulate=linear_emulator(prior, times))
    kw.update(likelihood=Likelihood(discrepancy="none", tolerances={}, model_error=0.0))

    def draws(stream):
        monkeypatch.setattr(sys, "stderr", stream)
        post = gpost.sample(one_experiment(times, length), **kw)
        return np.asarray(post.idata.posterior["Y"]), stream.getvalue()

    logged, log = draws(io.StringIO())
    shown, bars = draws(_Terminal())
    assert "\r" not in log and all(line.startswith("posterior: ") for line in log.splitlines())
    assert log.splitlines()[-1].startswith("posterior: NUTS done in ")
    assert "\r" in bars and "sample: 100%" in bars  # NumPyro's bar, at the end of its kept draws
    assert logged.shape == (2, 30) and np.std(logged) > 1.0  # Pa: the chains move
    np.testing.assert_allclose(shown, logged, rtol=1e-9, atol=0.0)
