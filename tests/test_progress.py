"""Progress output: bars on a terminal, a line every ~10 % on other streams, nothing when quiet."""

import io

from tqdm import tqdm

from growjax import progress as prog


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


def test_numpyro_progress_in_a_log_is_plain_lines_with_the_same_draws(monkeypatch, capsys):
    """Where stderr is not a terminal, NumPyro's bars become ~10 % lines; the sampler runs the same loop as with
    its bars, so the draws are equal bit for bit."""
    import jax
    import numpy as np
    import numpyro
    import numpyro.distributions as dist
    from numpyro.infer import MCMC, NUTS

    from growjax.posterior._sample import _numpyro_progress

    for name in ("CI", "PYTEST_XDIST_WORKER"):  # NumPyro turns its bars off under these
        monkeypatch.delenv(name, raising=False)
    data = np.random.default_rng(0).normal(1.0, 0.5, 30)

    def model(y):
        m = numpyro.sample("m", dist.Normal(0.0, 10.0))
        numpyro.sample("y", dist.Normal(m, 0.5), obs=y)

    def draws(patched: bool):
        mcmc = MCMC(NUTS(model), num_warmup=60, num_samples=60, num_chains=2, chain_method="vectorized")
        if patched:
            with _numpyro_progress(True):
                mcmc.run(jax.random.PRNGKey(3), data)
        else:
            mcmc.run(jax.random.PRNGKey(3), data)
        return np.asarray(mcmc.get_samples()["m"])

    bars = draws(False)
    capsys.readouterr()
    lines = draws(True)
    err = capsys.readouterr().err
    np.testing.assert_array_equal(lines, bars)
    assert "\r" not in err and len(err.splitlines()) == 10
    assert err.splitlines()[0].startswith("posterior: NUTS: 12/120 draws (10 %)") and err.endswith("sample\n")
