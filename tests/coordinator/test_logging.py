"""Messages and progress: -q/-v levels, a bar only on a terminal, one line per finished instance otherwise, one-line warnings."""

from __future__ import annotations

import fcntl
import io
import logging
import os
import pty
import struct
import subprocess
import sys
import termios
import threading
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest

from city.logs import BARS_ENV, LEVEL_ENV, LineFormatter, set_steps, setup, steps
from coordinator.cli import main
from coordinator.terminal import BarSafeHandler, bar, configure, inherit

TINY = ["--hours", "19", "--seeds", "2", "--taxis", "3", "--minutes", "3", "--policies", "greedy"]


@pytest.fixture(autouse=True)
def _back_to_info(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """A command run here sets the packages' level and the bar factory for the process: each test leaves them as it found them."""
    monkeypatch.setenv(LEVEL_ENV, "INFO")  # restored when the test ends, whatever the command exported
    yield
    setup("INFO")
    set_steps(None)


class FakeTerminal(io.StringIO):
    """A stream that says it is a terminal, as stderr is in an interactive shell."""

    def isatty(self) -> bool:
        return True


def test_quiet_leaves_warnings_and_errors_only(capsys: pytest.CaptureFixture) -> None:
    assert main(["-q", "evaluate", *TINY]) == 0
    err = capsys.readouterr().err
    assert "[1/2]" not in err and "hour 19 seed 0" not in err
    assert main(["evaluate", "--quiet", *TINY]) == 0  # after the command too
    assert "[1/2]" not in capsys.readouterr().err
    logging.getLogger("city.scenario").warning("still shown")
    assert capsys.readouterr().err == "surge: warning: still shown\n"


def test_default_shows_a_line_per_instance_and_verbose_adds_debug(capsys: pytest.CaptureFixture) -> None:
    assert main(["evaluate", *TINY]) == 0
    err = capsys.readouterr().err
    assert "[1/2] 2022-11-17 hour 19 seed 0: greedy=" in err and "[2/2]" in err
    assert "instances to run" not in err  # DEBUG
    assert main(["-v", "evaluate", *TINY]) == 0
    assert "2 instances to run (0 done), 1 worker process(es)" in capsys.readouterr().err


def test_no_bar_when_stderr_is_not_a_terminal(tmp_path: Path) -> None:
    """stderr to a pipe (CI, ``2> log``): no carriage returns of a bar, and the instance lines are the progress."""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    env.pop(LEVEL_ENV, None)
    done = subprocess.run([sys.executable, "-m", "coordinator.cli", "evaluate", *TINY], capture_output=True, text=True, env=env,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    assert "\r" not in done.stderr and "instance/s" not in done.stderr
    lines = done.stderr.splitlines()
    assert [line[:6] for line in lines if line.startswith("[")] == ["[1/2] ", "[2/2] "]
    assert "greedy" in done.stdout  # the table stays on stdout


def test_bar_on_a_terminal_with_eta() -> None:
    term = FakeTerminal()
    with bar(3, "instance", "evaluate", file=term) as b:
        for _ in range(3):
            b.update()
    shown = term.getvalue()
    assert "\r" in shown and "evaluate: 100%" in shown and "3/3 [" in shown and "<00:00" in shown  # elapsed<remaining: the ETA
    quiet = io.StringIO()
    with bar(3, "instance", "evaluate", file=quiet) as b:
        b.update(3)
    assert quiet.getvalue() == ""


def test_the_cli_wires_bars_to_library_steps_and_lines_above_them(monkeypatch: pytest.MonkeyPatch) -> None:
    term = FakeTerminal()
    monkeypatch.setattr(sys, "stderr", term)
    configure()
    with steps(2, "epoch", "train standard") as counted:
        counted.update()
        logging.getLogger("predictor.train").info("epoch 1 done")
        counted.update()
    shown = term.getvalue()
    assert "train standard: 100%" in shown and "2/2" in shown and "epoch 1 done\n" in shown
    assert isinstance(logging.getLogger("predictor").handlers[-1], BarSafeHandler)
    configure(quiet=True)
    with steps(2, "epoch", "quiet") as counted:
        counted.update(2)
    assert "quiet" not in term.getvalue()  # --quiet: no bars either


def test_lines_name_their_process_and_level() -> None:
    fmt = LineFormatter()

    def line(level: int, msg: str, **extra: str) -> str:
        record = logging.LogRecord("agents.taxi", level, __file__, 1, msg, None, None)
        record.__dict__.update(extra)
        return fmt.format(record)

    assert line(logging.INFO, "[1/4] 2022-11-17 hour 19 seed 0") == "[1/4] 2022-11-17 hour 19 seed 0"
    assert line(logging.WARNING, "left out 3 episodes") == "surge: warning: left out 3 episodes"
    assert line(logging.INFO, "joined run 'r'", who="agent 3") == "surge agent 3: joined run 'r'"
    assert line(logging.ERROR, "no such run", who="coordinator") == "surge coordinator: error: no such run"


def test_a_users_warning_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        assert main(["city", "--data", str(tmp_path)]) == 0
    err = capsys.readouterr().err.splitlines()
    assert err == [f"surge: warning: the synthetic scenario reads no data: --data {tmp_path} is not used "
                   "(give --scenario nyc or manhattan or a scenario file to use it)"]


def test_a_spawned_process_inherits_the_level_and_one_line_warnings() -> None:
    """What an evaluation worker or a fleet role does first (:func:`city.logs.inherit`): the parent's level, warnings in one line."""
    code = ("import logging, warnings; from city.logs import inherit; inherit(); warnings.warn('weather: 3 hours interpolated'); "
            "logging.getLogger('coordinator.x').info('hidden under -q')")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2]), LEVEL_ENV: "WARNING"}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=60)
    assert done.returncode == 0 and done.stderr == "surge: warning: weather: 3 hours interpolated\n", done.stderr


def test_a_spawned_worker_shows_bars_only_where_the_command_does(monkeypatch: pytest.MonkeyPatch) -> None:
    """The fleet's coordinator (:func:`coordinator.terminal.inherit`): the command's level, and its bars where it shows them."""
    monkeypatch.setattr(sys, "stderr", FakeTerminal())
    configure()
    assert os.environ[BARS_ENV] == "1"
    inherit()
    assert steps(3, "minute", "fleet").__class__.__name__ == "tqdm"
    assert isinstance(logging.getLogger("coordinator").handlers[-1], BarSafeHandler)
    configure(quiet=True)
    assert BARS_ENV not in os.environ
    inherit()
    assert steps(3, "minute", "fleet").__class__.__name__ == "_NoSteps"
    assert logging.getLogger("coordinator").level == logging.WARNING


def on_a_terminal(args: list[str], timeout: float = 300) -> tuple[int, str, str]:
    """Run ``args`` with stderr on a pseudo-terminal (120 columns), as in an interactive shell; (status, stdout, the terminal's text)."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 120, 0, 0))
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    for name in (LEVEL_ENV, BARS_ENV):
        env.pop(name, None)
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=slave, text=True, env=env)
    os.close(slave)
    shown: list[bytes] = []

    def drain() -> None:  # a full terminal buffer would block the command
        while True:
            try:
                data = os.read(master, 4096)
            except OSError:  # EIO: every process holding the terminal has exited
                return
            if not data:
                return
            shown.append(data)

    reader = threading.Thread(target=drain, daemon=True)
    reader.start()
    out, _ = proc.communicate(timeout=timeout)
    reader.join(10)
    os.close(master)
    return proc.returncode, out, b"".join(shown).decode(errors="replace")


def test_demo_shows_bars_for_the_fleets_minutes_replays_and_gif(tmp_path: Path) -> None:
    """The fleet's minutes count in its coordinator, a spawned process; the replays and the GIF's frames in the command."""
    status, out, term = on_a_terminal([sys.executable, "-m", "coordinator.cli", "demo", "--taxis", "2", "--minutes", "3",
                                       "--out", str(tmp_path)])
    assert status == 0, term
    assert "decisions identical" in out and "\r" in term
    for bar_text in ("run demo: 100%", "3/3 [", "minute/s", "in-process replay", "replay greedy", "frame/s"):
        assert bar_text in term, bar_text
    assert "minute 3/3" in term  # the log lines stay, above the bars


def test_bench_shows_a_bar_and_keeps_its_results_on_stdout() -> None:
    status, out, term = on_a_terminal([sys.executable, "-m", "coordinator.cli", "bench", "sim", "--taxis", "4", "--episodes", "2"])
    assert status == 0, term
    assert "bench sim" in term and "episode/s" in term and "2/2 [" in term
    assert "steps/s" in out and "steps/s" not in term
