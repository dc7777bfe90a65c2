"""The CLI without traps: --help of every command and subcommand, defaults shown, every flag checked, bad results files in one line."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from coordinator.cli import build_parser, main


def _commands(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    out = [path]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                out += _commands(sub, (*path, name))
    return out


COMMANDS = _commands(build_parser())


def test_every_command_is_listed() -> None:
    assert {c[0] for c in COMMANDS if c} >= {"evaluate", "report", "city", "demand", "demo", "bench", "fleet", "reproduce", "predictor"}
    assert ("predictor", "eval") in COMMANDS and ("bench", "plan") in COMMANDS


@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: " ".join(c) or "surge")
def test_help_of_every_command(command: tuple[str, ...], capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as done:
        main([*command, "--help"])
    assert done.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: surge")


def test_help_shows_defaults(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "(default: synthetic)" in out and "(default: 25)" in out


@pytest.mark.parametrize("argv", [["evaluate", "--policies", "greedy", "--forecast", "magic"],
                                  ["fleet", "--forecast", "magic"],
                                  ["bench", "plan", "--forecast", "magic"],
                                  ["predictor", "serve", "--run", "r", "--forecast", "magic"]])
def test_an_unknown_forecast_is_refused_whichever_policies_run(argv: list[str], capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as done:
        main(argv)
    assert done.value.code == 2
    assert "unknown forecast 'magic'" in capsys.readouterr().err


def test_a_model_flag_must_name_a_trained_predictor(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit):
        main(["evaluate", "--policies", "greedy", "--model", str(tmp_path)])
    assert "not a trained predictor directory" in capsys.readouterr().err


@pytest.mark.parametrize("mutate", [
    lambda d: d["episodes"][0].__setitem__("total_cost", "lots"),
    lambda d: d["episodes"][0].__setitem__("seed", None),
    lambda d: d.__setitem__("episodes", {"a": 1}),
    lambda d: d["episodes"][0].__setitem__("date", 7),
    lambda d: d.__setitem__("config", []),
])
def test_report_answers_a_bad_results_file_in_one_line(mutate, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    good = tmp_path / "good.json"
    assert main(["evaluate", "--hours", "19", "--seeds", "1", "--taxis", "3", "--minutes", "3", "--policies", "greedy", "--json", str(good)]) == 0
    doc = json.loads(good.read_text())
    mutate(doc)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    capsys.readouterr()
    assert main(["report", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"surge: error: {bad}") and "\n" not in err and "Traceback" not in err


@pytest.mark.parametrize("command", ["fleet", "demo"])
def test_port_flag_is_checked_before_anything_starts(command: str, tmp_path: Path, capsys: pytest.CaptureFixture,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    import socket

    from city.scenario import SHARE_ENV

    monkeypatch.setenv(SHARE_ENV, "1")  # recorded, so the --share the demo exports is undone after the test
    monkeypatch.delenv(SHARE_ENV)

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        extra = ["--taxis", "2", "--minutes", "2"] + (["--out", str(tmp_path / "demo")] if command == "demo" else [])
        assert main([command, "--insecure", "--port", str(port), *extra]) == 2
    assert f"--port {port}: cannot listen on 127.0.0.1:{port}" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([command, "--port", "70000"])
    assert "port 70000 is outside 1..65535" in capsys.readouterr().err
