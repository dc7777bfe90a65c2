"""``surge reproduce`` end to end at smoke size: results, figures, the report with computed verdicts, and resuming."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from coordinator.cli import main
from coordinator.experiments.results import RESULTS_SCHEMA


def test_reproduce_smoke_writes_the_report_and_resumes(tmp_path: Path, capsys, monkeypatch: pytest.MonkeyPatch) -> None:
    from coordinator.experiments.protocol import Run

    out = tmp_path / "r"
    say = Run.say

    def stop_after_the_ablation_instance(run: Run, msg: str) -> None:
        say(run, msg)
        if msg.startswith("ablation [1/1]"):
            raise KeyboardInterrupt  # as Ctrl-C or SIGTERM would, with the instance checkpointed

    with monkeypatch.context() as m:
        m.setattr(Run, "say", stop_after_the_ablation_instance)
        assert main(["reproduce", "--smoke", "--out", str(out)]) == 130
    stopped = json.loads((out / "timings.json").read_text())["all invocations"]
    assert stopped["main"] > 0 and stopped["ablation"] > 0 and "report" not in stopped  # the stopped step's seconds count
    capsys.readouterr()
    assert main(["reproduce", "--smoke", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "main resuming from" in err and "[1/" not in err  # every instance was done: nothing ran again
    summed = json.loads((out / "timings.json").read_text())["all invocations"]
    assert summed["ablation"] >= stopped["ablation"] and summed["report"] > 0
    report = (out / "REPORT.md").read_text()
    for section in ("Verdicts", "Table 1", "Table 2", "Table 3", "Table 4", "Data provenance", "paired bootstrap",
                    "What rollout gains over its own base policy", "| 19h | `surge:base=ia` − `ia` |",
                    "Planning seconds summed over the episodes of the results"):
        assert section in report
    assert report.count("**held**") + report.count("**not held**") == 3
    assert "## Against the state of practice" in report and "| 19h | `surge` − `rebalance` |" in report
    assert report.count("19 h: surge beats the strongest practical baseline: ") == 1  # one computed verdict per hour
    assert "no predictor in this protocol" in report  # the smoke protocol says what surge planned with
    assert "timed on one machine" in report  # the planning verdict compares rows of one machine
    for name in ("fig-total-cost.png", "fig-wait-overhead.png", "fig-surge-map.png", "surge-vs-greedy.gif"):
        assert (out / name).stat().st_size > 1000, name
    main_doc = json.loads((out / "results-main.json").read_text())
    assert main_doc["schema"] == RESULTS_SCHEMA and main_doc["reference_oracle"] == "oracle"
    assert {"match", "rebalance"} <= set(main_doc["config"]["policies"])
    assert main_doc["config"]["policy_options"]["rebalance"] == {"forecast": "true-rate"}  # surge's forecast in this protocol
    assert main(["reproduce", "--smoke", "--out", str(out), "--report-only"]) == 0
    assert "## Status: interim" not in (out / "REPORT.md").read_text()  # every step is done: the report is final
    capsys.readouterr()
    (out / "results-ablation.json").unlink()  # as if the run had stopped before its ablations
    assert main(["reproduce", "--smoke", "--out", str(out), "--report-only"]) == 0
    err = capsys.readouterr().err
    assert "[1/" not in err and "(interim)" in err  # nothing ran
    report = (out / "REPORT.md").read_text()
    assert "## Status: interim" in report and "- main: 1 of 1 instances" in report
    assert "- ablation: 0 of 1 instances (not started)" in report and "Table 1" in report
    assert not (out / "results-ablation.json").exists()


def test_report_only_needs_the_main_results(tmp_path: Path, capsys) -> None:
    assert main(["reproduce", "--smoke", "--out", str(tmp_path / "empty"), "--report-only"]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "results-main.json: no results yet; run `surge reproduce` without --report-only" in err[0]
    assert not (tmp_path / "empty").exists()


def test_results_of_another_predictor_are_refused_or_refreshed(tmp_path: Path) -> None:
    import pytest
    import torch

    from city.errors import ConfigError
    from coordinator.experiments.evaluate import EvalConfig, evaluate
    from coordinator.experiments.results import read_results, write_json
    from coordinator.experiments.protocol import SMOKE, Run
    from coordinator.experiments.reproduce import _check_model, model_fingerprint

    model, out = tmp_path / "model", tmp_path / "out"
    model.mkdir()
    out.mkdir()
    torch.save({"w": torch.arange(4.0)}, model / "standard.pt")
    doc = evaluate(EvalConfig(hours=[19], seeds=1, taxis=8, minutes=4, policies=["greedy", "ia"], policy_options={"oracle": {"iters": 20}}),
                   progress=lambda _m: None)
    doc["config"]["policy_options"]["ia"] = {"model": str(model)}  # as if ia planned with the predictor
    write_json(doc, out / "results-main.json")
    (out / "predictor-eval.json").write_text("{}")
    run = Run(out=out, scenario="synthetic", data=None, protocol=replace(SMOKE, predictor=True), model_dir=model)
    with pytest.raises(ConfigError, match="not recorded.*--refresh-model"):
        _check_model(run, refresh=False)
    _check_model(run, refresh=True)
    assert [e["policy"] for e in read_results(out / "results-main.json")["episodes"]] == ["greedy"]
    assert not (out / "predictor-eval.json").exists()
    assert (out / "model.sha256").read_text().strip() == model_fingerprint(model)
    _check_model(run, refresh=False)  # the same predictor: nothing to say
    torch.save({"w": torch.arange(5.0)}, model / "standard.pt")
    with pytest.raises(ConfigError, match="recorded [0-9a-f]{12}"):
        _check_model(run, refresh=False)


def test_the_pruning_ablation_runs_at_one_sample_count_pruned_and_unpruned() -> None:
    from coordinator.experiments.protocol import FULL, QUICK, pruning_pairs

    assert pruning_pairs(FULL) == [("surge:prune=none,samples=100", "surge:samples=100"),
                                   ("garces2023:prune=none,samples=100", "garces2023:samples=100")]
    assert pruning_pairs(QUICK) == [("surge:prune=none,samples=30", "surge:samples=30"),
                                    ("garces2023:prune=none,samples=30", "garces2023:samples=30")]
    assert pruning_pairs(replace(QUICK, samples=20)) == [("surge:prune=none", "surge"), ("garces2023:prune=none", "garces2023")]


def test_the_protocol_plans_every_surge_label_exactly_and_resumes_the_committed_reports(tmp_path: Path) -> None:
    """surge's default approximations stay out of the paper's protocol, and the committed reports' rows still count as its own."""
    from agents.base import parse_policy, policy_class
    from coordinator.experiments.results import read_results
    from coordinator.experiments.protocol import ABLATIONS, FULL, MAIN_POLICIES, QUICK, Run, policy_options, pruning_pairs

    run = Run(out=tmp_path, scenario="synthetic", data=None, protocol=FULL)
    labels = [*MAIN_POLICIES, *ABLATIONS, *(label for pair in pruning_pairs(FULL) for label in pair)]
    options = policy_options(run, labels)
    for label in labels:
        name, own = parse_policy(label)
        if name not in ("surge", "garces2023"):
            continue
        planner = {k: v for k, v in {**options.get(label, {}), **own}.items() if k not in ("forecast", "model")}
        config = policy_class(name).rollout_config(**planner)
        assert config.adaptive is None and config.cap is None, label
    for part in ("main", "ablation"):
        doc = read_results(Path(__file__).parents[2] / "benchmarks" / "paper-protocol" / "quick-synthetic" / f"results-{part}.json")
        model = next(o["model"] for o in doc["config"]["policy_options"].values() if "model" in o)
        quick = Run(out=tmp_path, scenario="synthetic", data=None, protocol=QUICK, model_dir=Path(model))
        assert policy_options(quick, [*doc["config"]["policies"], "oracle"]) == doc["config"]["policy_options"], part


def test_rebalance_plans_with_the_trained_model_where_surge_does_and_competes_in_the_verdict(tmp_path: Path) -> None:
    """``rebalance``'s own default forecast is previous-hour: the protocol must name the model, or the verdict drops it."""
    from coordinator.experiments.practice import practical_labels
    from coordinator.experiments.protocol import QUICK, Run, policy_options

    run = Run(out=tmp_path, scenario="synthetic", data=None, protocol=QUICK)
    options = policy_options(run, ["surge", "rebalance", "match"])
    assert options["rebalance"] == {"forecast": "model", "model": str(tmp_path / "model")}
    assert options["surge"]["model"] == str(tmp_path / "model") and "forecast" not in options["surge"]  # its default
    doc = {"config": {"policy_options": options},
           "episodes": [{"policy": p, "hour": 19, "seed": 0, "date": "2022-11-17"} for p in ("surge", "rebalance", "match")]}
    assert practical_labels(doc, "surge") == ["rebalance", "match"]


def _row(step_policy: str, seed: int, seconds: float, machine: str | None) -> dict:
    row = {"date": "2022-11-17", "hour": 19, "seed": seed, "policy": step_policy, "plan_seconds_per_step": seconds}
    if machine:
        row["machine"] = machine
    return row


def test_the_planning_verdict_compares_rows_timed_on_one_machine() -> None:
    from coordinator.experiments.report import planning_ratio

    # The main run's surge rows were rerun on a slower machine: comparing them with garces2023's measures the machines.
    main = {"episodes": [_row("surge", s, 2.0, "slow x2") for s in range(3)] + [_row("garces2023", s, 3.0, "fast x2") for s in range(3)]}
    ablation = {"episodes": [_row("surge:forecast=true-rate", s, 1.0, "slow x2") for s in range(2)]
                + [_row("garces2023:forecast=true-rate", s, 4.0, "slow x2") for s in range(2)]}
    ratio, why = planning_ratio({"main": main, "ablation": ablation})
    assert ratio == 0.25 and "over the 2 instances of the ablation step" in why and "(slow x2)" in why
    ratio, why = planning_ratio({"main": main, "ablation": {"episodes": []}})
    assert ratio == 2.0 / 3.0 and "may compare machines" in why  # no pair of one machine: said, not hidden


def test_the_planning_verdict_prefers_cpu_seconds_where_pairs_have_them() -> None:
    from coordinator.experiments.report import planning_ratio

    # Wall seconds of a run that was paused or shared its cores are inflated; CPU seconds are not.
    main = {"episodes": [{**_row("surge", s, 5.0, "m x2"), "plan_cpu_seconds_per_step": 1.0} for s in range(2)]
            + [{**_row("garces2023", s, 5.0, "m x2"), "plan_cpu_seconds_per_step": 2.0} for s in range(2)]}
    ratio, why = planning_ratio({"main": main, "ablation": {"episodes": []}})
    assert ratio == 0.5 and "CPU s per step" in why
    main["episodes"][0].pop("plan_cpu_seconds_per_step")  # one row from before CPU seconds were recorded: its pair is left out
    main["episodes"][1]["plan_cpu_seconds_per_step"] = 3.0
    ratio, why = planning_ratio({"main": main, "ablation": {"episodes": []}})
    assert ratio == 1.5 and "over the 1 of 2 instances with CPU seconds" in why
    for e in main["episodes"]:
        e.pop("plan_cpu_seconds_per_step", None)  # none has them: wall seconds
    ratio, why = planning_ratio({"main": main, "ablation": {"episodes": []}})
    assert ratio == 1.0 and "CPU" not in why


def test_the_ia_explanation_names_only_differences_clear_at_every_hour() -> None:
    from coordinator.experiments.report import ia_explanation
    from coordinator.experiments.protocol import CE_LABELS

    limited, counts = CE_LABELS
    costs = {"ia": 100, "garces2023": 99, "garces2023:forecast=model": 99, counts: 99, limited: 90, "surge:base=ia": 89}
    rows = [{"date": "2022-11-17", "hour": h, "seed": s, "policy": p, "total_cost": c + s % 3 + (h == 19) * (p == "surge:base=ia") * 20,
             "outstanding_end": 0, "served": 10, "wait_overhead_per_served": float(c), "plan_seconds_per_step": 0.0,
             "oracle_cost": 0, "oracle_auction_cost": 0}
            for h in (17, 19) for s in range(6) for p, c in costs.items()]
    text = "\n".join(ia_explanation({"episodes": rows}, *CE_LABELS))
    assert "clear at every ablation hour: random counts" in text  # not the places: counts − model is 0
    assert "local sampling" in text.split("clear at every ablation hour:")[0]  # listed as a row, not as clear (worse at 19 h)
    assert "does not gain clearly at every hour" in text  # surge:base=ia is +9 at 19 h
    assert ia_explanation({"episodes": []}, *CE_LABELS)[-1] == "No instance has these rows yet."
    few = [e for e in rows if e["seed"] < 4]  # 4 instances an hour: too few to call any effect clear
    text = "\n".join(ia_explanation({"episodes": few}, *CE_LABELS))
    assert "none of the four differences is clear at every hour" in text and "fewer than 5: not judged" in text


def test_surge_meets_the_strongest_practical_baseline_of_each_hour_with_the_same_forecast() -> None:
    """The strongest is chosen per hour among the baselines with surge's forecast (or none); the verdict needs a CI below zero."""
    from coordinator.experiments.practice import against_practice, report_section, verdict_lines

    costs = {17: {"surge": 100, "match": 130, "rebalance": 110, "rebalance:forecast=true-rate": 50},
             19: {"surge": 100, "match": 95, "rebalance": 120, "rebalance:forecast=true-rate": 50}}
    rows = [{"date": "2022-11-17", "hour": h, "seed": s, "policy": p, "total_cost": c + (s % 3) * (p == "surge"), "outstanding_end": 0,
             "served": 10, "wait_overhead_per_served": 1.0, "oracle_cost": 0} for h, by in costs.items() for p, c in by.items() for s in range(6)]
    doc = {"config": {"policies": list(costs[17]), "policy_options": {"surge": {"forecast": "previous-hour"}}}, "episodes": rows}
    got = {r["hour"]: r for r in against_practice(doc, "surge")}
    assert got[17]["strongest"] == "rebalance" and got[17]["beats"] and got[17]["wins"] == 6  # true-rate's row is other information
    assert got[19]["strongest"] == "match" and not got[19]["beats"] and got[19]["wins"] == 0
    lines = verdict_lines(list(got.values()))
    assert lines[0].startswith("17 h: surge beats the strongest practical baseline: yes (strongest rebalance, forecast previous-hour")
    assert lines[1].startswith("19 h: surge beats the strongest practical baseline: no (strongest match")
    few = {**doc, "episodes": [e for e in rows if e["seed"] < 3]}
    assert not any(r["beats"] for r in against_practice(few, "surge"))  # 3 instances: not judged
    assert "| 17h | `rebalance` | 110.0 |" in "\n".join(report_section(doc))
