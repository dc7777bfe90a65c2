"""``surge reproduce`` end to end at smoke size: results, figures, the report with computed verdicts, and resuming."""

from __future__ import annotations

import json
from pathlib import Path

from coordinator.cli import main
from coordinator.evaluate import RESULTS_SCHEMA


def test_reproduce_smoke_writes_the_report_and_resumes(tmp_path: Path, capsys) -> None:  # noqa: ANN001
    out = tmp_path / "r"
    assert main(["reproduce", "--smoke", "--out", str(out)]) == 0
    report = (out / "REPORT.md").read_text()
    for section in ("Verdicts", "Table 1", "Table 2", "Table 3", "Table 4", "Data provenance", "paired bootstrap"):
        assert section in report
    assert report.count("**held**") + report.count("**not held**") == 3
    assert "no predictor in this protocol" in report  # the smoke protocol says what surge planned with
    for name in ("fig-total-cost.png", "fig-wait-overhead.png", "fig-surge-map.png", "surge-vs-greedy.gif"):
        assert (out / name).stat().st_size > 1000, name
    main_doc = json.loads((out / "results-main.json").read_text())
    assert main_doc["schema"] == RESULTS_SCHEMA and main_doc["reference_oracle"] == "oracle"
    capsys.readouterr()
    assert main(["reproduce", "--smoke", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "main resuming from" in err and "[1/" not in err.split("ablation")[0]  # finished episodes are not rerun
