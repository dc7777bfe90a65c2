"""docs/results.md is generated from the committed result files, and a benchmark folder adds a section by a page.toml."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from city.errors import ConfigError
from coordinator.experiments import results_page

ROOT = Path(__file__).parents[2]


def test_the_committed_results_page_is_what_the_committed_results_give() -> None:
    page = ROOT / "docs" / "results.md"
    expected = results_page.render(ROOT / "benchmarks", rel="../benchmarks")
    assert page.read_text() == expected, "docs/results.md is stale: run `surge report --results-page` and commit it"


def _folder(root: Path, toml: str, doc: dict) -> Path:
    folder = root / "my-question"
    folder.mkdir(parents=True)
    (folder / "run.json").write_text(json.dumps(doc))
    (folder / "page.toml").write_text(toml)
    return folder


def test_a_folder_adds_a_section_with_a_page_toml_alone(tmp_path: Path) -> None:
    _folder(tmp_path, """
[[section]]
title = "Minutes per episode"
kind = "fields"
files = ["run.json"]
columns = [{head = "policy", path = "policy"}, {head = "minutes", path = "seconds", scale = 0.5, fmt = "{:.2f}"},
           {head = "median step", path = "steps", agg = "median", fmt = "{:.1f}"}]
""", {"command": "surge something --json run.json", "date": "2026-12-06", "machine": "2-vCPU x86_64",
      "policy": "surge", "seconds": 3.0, "steps": [1.0, 2.0, 9.0]})
    page = results_page.render(tmp_path)
    assert "## Minutes per episode" in page
    assert "| surge | 1.50 | 2.0 |" in page
    assert "Ran 2026-12-06 on a 2-vCPU x86_64" in page and "surge something --json run.json" in page
    assert "(../benchmarks/my-question/run.json)" in page


def test_a_mapping_of_rows_gives_a_row_per_key(tmp_path: Path) -> None:
    _folder(tmp_path, """
[[section]]
title = "Error by hour"
kind = "fields"
files = ["run.json"]
rows = "by_hour"
columns = [{head = "hour", path = "$key"}, {head = "error", path = "nn.pe", fmt = "{:.1f} %"}]
""", {"command": "c", "date": "2026-12-06", "machine": "m",
      "by_hour": {"17": {"nn": {"pe": 11.37}}, "19": {"nn": {"pe": 14.4}}}})
    page = results_page.render(tmp_path)
    assert "| 17 | 11.4 % |" in page and "| 19 | 14.4 % |" in page


def test_a_section_without_provenance_is_refused_in_one_line(tmp_path: Path) -> None:
    _folder(tmp_path, '[[section]]\ntitle = "T"\nkind = "fields"\nfiles = ["run.json"]\ncolumns = [{head = "x", path = "x"}]\n',
            {"x": 1, "date": "2026-12-06"})
    with pytest.raises(ConfigError, match=r"my-question/page.toml, section 1: key 'command' is missing"):
        results_page.render(tmp_path)


def test_an_unknown_kind_or_path_names_the_page_and_the_key(tmp_path: Path) -> None:
    folder = _folder(tmp_path, '[[section]]\ntitle = "T"\nkind = "pie"\nfiles = ["run.json"]\n', {"x": 1})
    with pytest.raises(ConfigError, match="unknown kind 'pie'"):
        results_page.render(tmp_path)
    (folder / "page.toml").write_text('[[section]]\ntitle = "T"\nkind = "fields"\nfiles = ["run.json"]\ncommand = "c"\n'
                                      'date = "d"\nmachine = "m"\ncolumns = [{head = "y", path = "a.b"}]\n')
    with pytest.raises(ConfigError, match=r"file run.json: path 'a.b': no 'a'"):
        results_page.render(tmp_path)


def test_a_new_kind_registers_from_the_module_a_page_names(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "my_kinds.py").write_text(
        "from coordinator.experiments.results_page import renderer\n\n"
        "@renderer('shout')\ndef shout(sec):\n    return [sec.load('run.json')['word'].upper()]\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    _folder(tmp_path / "benchmarks", '[[section]]\ntitle = "T"\nkind = "shout"\nmodule = "my_kinds"\nfiles = ["run.json"]\n',
            {"word": "surge", "command": "c", "date": "2026-12-06", "machine": "m"})
    assert "SURGE" in results_page.render(tmp_path / "benchmarks")
    results_page.RENDERERS.pop("shout")


def test_paired_results_by_date_and_the_gap_closed(tmp_path: Path) -> None:
    """Two dates in one results file: a row per date and hour, and each policy's share of the greedy→oracle gap."""
    from coordinator.experiments.evaluate import EvalConfig, evaluate

    doc = evaluate(EvalConfig(dates=["2022-11-17", "2022-11-18"], hours=[19], seeds=2, taxis=4, minutes=6,
                              policies=["greedy", "ia"]), progress=lambda _m: None)
    _folder(tmp_path, """
[[section]]
title = "By date"
kind = "paired-results"
files = ["run.json"]
labels = ["city"]
policy = "ia"
against = "greedy"
by_date = true
command = "c"
date = "2026-12-06"
machine = "m"

[[section]]
title = "Gap"
kind = "gap-closed"
files = ["run.json"]
labels = ["city"]
policies = ["ia", "greedy"]
command = "c"
date = "2026-12-06"
machine = "m"
""", doc)
    page = results_page.render(tmp_path)
    assert "| city, 2022-11-17 | 19 h | " in page and "| city, 2022-11-18 | 19 h | " in page
    eps = doc["episodes"]

    def mean(policy: str, key: str = "total_cost") -> float:
        return sum(e[key] for e in eps if e["policy"] == policy) / 4

    share = 100 * (mean("greedy") - mean("ia")) / (mean("greedy") - mean("greedy", "oracle_cost"))
    assert f"| city | 19 h | 4 | {results_page.fmt(share, '{:.1f} %')} | 0.0 % |" in page
    # A policy that ran on some instances only: every share of the row is over those instances.
    part = {**doc, "episodes": [e for e in eps if not (e["policy"] == "ia" and e["seed"] == 1)]}
    folder = tmp_path / "my-question"
    (folder / "run.json").write_text(json.dumps(part))
    assert "| city | 19 h | 2 |" in results_page.render(tmp_path)


def test_surge_report_results_page_writes_the_page_and_says_when_it_is_current(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from coordinator.cli import main

    _folder(tmp_path / "benchmarks", '[[section]]\ntitle = "T"\nkind = "fields"\nfiles = ["run.json"]\n'
            'columns = [{head = "x", path = "x"}]\n', {"x": 7, "command": "c", "date": "2026-12-06", "machine": "m"})
    args = ["report", "--results-page", "--benchmarks", str(tmp_path / "benchmarks"), "--out", str(tmp_path / "docs" / "results.md")]
    assert main(args) == 0
    assert "| 7 |" in (tmp_path / "docs" / "results.md").read_text() and "wrote" in capsys.readouterr().out
    assert main(args) == 0
    assert "is up to date" in capsys.readouterr().out
    assert main(["report"]) == 2
    assert "give a results file (or --results-page)" in capsys.readouterr().err
