"""Stopping and keeping (issue 17, item 4): Ctrl-C (SIGINT) stops every method, in the API and the
CLI, compiled drivers included, and the partial trajectory is handed over (on the exception, or
written by the CLI); an exception in a callback keeps the partial trajectory too."""

from __future__ import annotations

import os
import pty
import re
import select
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

import kronlag
from kronlag.app.cli import EXIT_INTERRUPTED
from kronlag.model.builtin import load_example
from kronlag.simulation import METHODS

#: Generous bound on the time from SIGINT to the end of the process (the runs stop within a fraction
#: of a second; the bound only keeps a broken build from hanging the suite).
STOP_BOUND = 30.0

#: Bound on the start of a subprocess (derivation and compilation with a cold cache).
START_BOUND = 600.0

#: A run that would take hours: Ctrl-C has to end it.
LONG = 1e6

#: The first output time after 0 of the CLI's default grid over [0, LONG] (100 001 points): a run
#: stopped before it saves t = 0 alone (on a loaded machine the progress bar can appear before).
FIRST_OUTPUT = LONG / 100_000


@pytest.fixture(scope="module")
def four_bar():
    example = load_example("four_bar", apply_drives=False)
    return example, example.numeric_values()


def _start(example, values, **changes):
    model = kronlag.derive(example.system).numeric({**values, **changes})
    q0, qd0 = model.assemble([1.0, 0.5, 1.5], fixed={"q1": 1.0}, qd_fixed={"q1": 6.0})
    return model, q0, qd0


@pytest.mark.parametrize("method", list(METHODS))
def test_sigint_during_a_run_hands_over_the_partial_trajectory(four_bar, method):
    model, q0, qd0 = _start(*four_bar)

    def interrupt_at_half_a_second(t):
        if t > 0.5 and not interrupt_at_half_a_second.sent:
            interrupt_at_half_a_second.sent = True
            os.kill(os.getpid(), signal.SIGINT)
        elif t > 100.0:  # a failure, not a run of hours, if the signal was not acted upon
            raise AssertionError(f"SIGINT sent at t > 0.5 not acted upon by t = {t} "
                                 f"(SIGINT handler: {signal.getsignal(signal.SIGINT)!r})")

    interrupt_at_half_a_second.sent = False
    with pytest.raises(KeyboardInterrupt, match="simulation interrupted at t = ") as caught:
        kronlag.simulate(model, (0.0, LONG), q0, qd0, method=method, progress=interrupt_at_half_a_second,
                         max_steps=10**12)
    trajectory = caught.value.trajectory
    assert type(caught.value) is KeyboardInterrupt  # a program that does not catch it ends by SIGINT
    assert trajectory.result is kronlag.Result.INTERRUPTED and trajectory.status == -1
    assert "interrupted" in trajectory.message
    assert 0.5 < trajectory.t[-1] < 10.0 and len(trajectory.t) == len(trajectory.q) > 1
    assert np.all(np.isfinite(trajectory.q)) and np.abs(trajectory.position_residual).max() < 1e-6
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # restored


def _raising_torque(t: float) -> float:
    if t > 0.5:
        raise ValueError("torque table ends at t = 0.5")
    return 1.0


@pytest.mark.parametrize("method", ["baumgarte", "projection", "ggl"])  # the compiled ones need constants
def test_an_exception_in_a_parameter_callback_keeps_the_partial_trajectory(four_bar, method):
    model, q0, qd0 = _start(*four_bar, tau=_raising_torque)
    with pytest.raises(ValueError, match="torque table ends") as caught:
        kronlag.simulate(model, (0.0, 2.0), q0, qd0, method=method)
    trajectory = caught.value.trajectory
    assert trajectory.result is kronlag.Result.RAISED
    assert "ValueError: torque table ends at t = 0.5" in trajectory.message
    assert 0.0 < trajectory.t[-1] <= 0.5 and np.all(np.isfinite(trajectory.q))
    assert any("partial trajectory" in note for note in caught.value.__notes__)


@pytest.mark.parametrize("method", ["compiled", "ali3p", "switching"])
def test_an_exception_in_progress_ends_a_compiled_run_and_keeps_it(four_bar, method):
    model, q0, qd0 = _start(*four_bar)

    def progress(t):
        if t > 0.5:
            raise RuntimeError("progress display closed")

    with pytest.raises(RuntimeError, match="display closed") as caught:
        kronlag.simulate(model, (0.0, 20.0), q0, qd0, method=method, progress=progress)
    trajectory = caught.value.trajectory
    assert trajectory.result is kronlag.Result.RAISED
    assert 0.5 < trajectory.t[-1] < 20.0


_API_RUN = textwrap.dedent("""
    import signal, sys, threading, time
    import numpy as np, kronlag
    from kronlag.model.builtin import load_example

    LONG = float(sys.argv[2])
    example = load_example("four_bar", apply_drives=False)
    model = kronlag.derive(example.system).numeric(example.numeric_values())
    q0, qd0 = model.assemble([1.0, 0.5, 1.5], fixed={"q1": 1.0}, qd_fixed={"q1": 6.0})

    def announce():  # the run has started once simulate has taken over SIGINT
        while signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            time.sleep(0.01)
        print("running", flush=True)

    threading.Thread(target=announce, daemon=True).start()
    try:
        kronlag.simulate(model, (0.0, LONG), q0, qd0, method=sys.argv[1],
                         t_eval=np.linspace(0.0, 1000.0, 100001), max_steps=10**12)
    except KeyboardInterrupt as interrupt:
        trajectory = interrupt.trajectory
        print("interrupted", trajectory.result.name, len(trajectory.t), trajectory.t[-1], flush=True)
        raise
    print("finished", flush=True)
""")


def _line(stream, timeout: float) -> str:
    """The next line of a subprocess's text ``stream``, waiting at most ``timeout`` seconds."""
    ready, _, _ = select.select([stream], [], [], timeout)
    assert ready, f"no output within {timeout} s"
    return stream.readline()


@pytest.mark.slow
@pytest.mark.parametrize("method", ["compiled", "baumgarte"])
def test_sigint_stops_an_api_run_in_a_subprocess(method):
    """No progress callback: the compiled driver is stopped by its poll of Python, the Python loop
    by the handler's flag; the process ends by the KeyboardInterrupt after the partial result."""
    process = subprocess.Popen([sys.executable, "-c", _API_RUN, method, str(LONG)], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    try:
        assert _line(process.stdout, START_BOUND) == "running\n"
        time.sleep(1.0)  # well into the integration
        process.send_signal(signal.SIGINT)
        sent = time.perf_counter()
        report = _line(process.stdout, STOP_BOUND).split()
        process.wait(STOP_BOUND)
        print(f"{method}: stopped {time.perf_counter() - sent:.3f} s after SIGINT")
    finally:
        process.kill()
        process.communicate()
    assert report[:2] == ["interrupted", "INTERRUPTED"], report
    assert int(report[2]) > 1 and 0.0 < float(report[3]) < LONG
    assert process.returncode == -signal.SIGINT  # the KeyboardInterrupt, re-raised, ends the program


@pytest.mark.slow
def test_sigint_stops_the_cli_which_writes_the_partial_run(tmp_path):
    """A terminal on stderr: the progress bar, drawn from inside the run, says it has passed its first
    output time."""
    output = tmp_path / "run.npz"
    controller, terminal = pty.openpty()
    process = subprocess.Popen([sys.executable, "-m", "kronlag", "simulate", "four_bar", "--t-end", f"{LONG:g}",
                                "--output", str(output)], stdout=subprocess.PIPE, stderr=terminal, text=True,
                               cwd=tmp_path)
    os.close(terminal)
    seen = b""
    try:
        while not any(float(t) > FIRST_OUTPUT for t in re.findall(rb"t = (\S+) /", seen)):
            ready, _, _ = select.select([controller], [], [], START_BOUND)
            assert ready, "the progress bar did not appear"
            seen += os.read(controller, 4096)
        process.send_signal(signal.SIGINT)
        sent = time.perf_counter()
        stdout, _ = process.communicate(timeout=STOP_BOUND)
        print(f"cli: ended {time.perf_counter() - sent:.3f} s after SIGINT")
        while True:
            try:
                chunk = os.read(controller, 4096)
            except OSError:  # the terminal's other side is closed
                break
            if not chunk:
                break
            seen += chunk
    finally:
        process.kill()
        os.close(controller)
    stderr = seen.decode().replace("\r\n", "\n")
    last = stderr.strip().splitlines()[-1]
    assert process.returncode == EXIT_INTERRUPTED, stderr
    assert last.startswith("kronlag: Integration stopped at t = ") and "interrupted (Ctrl-C, SIGINT)" in last
    assert f"the results are saved in {output}" in last and "Traceback" not in stderr
    assert "status: FAILED" in stdout
    with np.load(output) as saved:
        assert 0.0 < saved["t"][-1] < LONG and len(saved["t"]) > 1
        assert "interrupted" in str(saved["message"])


def test_a_keyboard_interrupt_outside_a_run_is_one_line(monkeypatch, capsys):
    from kronlag.app import cli, commands

    def interrupted(arguments):
        raise KeyboardInterrupt

    monkeypatch.setattr(commands, "_models", interrupted)
    assert cli.main(["models"]) == EXIT_INTERRUPTED
    assert capsys.readouterr().err == "kronlag: interrupted\n"


def test_interrupted_result_has_a_driver_code():
    from kronlag.simulation.interface import c_declarations

    declarations = c_declarations()
    assert f"#define KRONLAG_RESULT_INTERRUPTED ({kronlag.Result.INTERRUPTED.code})" in declarations
    assert kronlag.Result.of_code(kronlag.Result.INTERRUPTED.code) is kronlag.Result.INTERRUPTED
