"""What watching costs a fleet: its median minute with and without `surge watch` (and a headless browser on its page) attached.

``--no-browser`` attaches the watch server alone (an operator's browser on another machine).

Runs the same secured run (router, coordinator, one process per taxi, all on
this host) alternately without and with a watcher, ``--rounds`` times each,
and writes every run's minute times and the paired differences.

usage: python benchmarks/watch-cost/run.py --taxis 20 --minutes 20 --rounds 2 --json benchmarks/watch-cost/watch-cost.json
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from bus.certs import make_certs
from bus.router import free_tcp_port, wait_for_tcp

CLI = [sys.executable, "-m", "coordinator.cli"]


def browser(url: str, profile: str):
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = "/usr/bin/chromium"
    for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--window-size=1450,900", f"--user-data-dir={profile}"):
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)
    driver.get(url)
    return driver


def one_run(args: argparse.Namespace, watched: bool, tmp: Path) -> dict:
    certs, result = tmp / "certs", tmp / "result.json"
    if not certs.exists():
        make_certs(certs, args.taxis)
    port = free_tcp_port()
    endpoint = f"tls/127.0.0.1:{port}"
    bus = ["--connect", endpoint, "--certs", str(certs)]
    run = f"cost{int(time.time())}"
    procs = [subprocess.Popen([*CLI, "router", "--certs", str(certs), "--listen", endpoint], stderr=subprocess.DEVNULL)]
    driver, frames, shown = None, None, None
    try:
        wait_for_tcp("127.0.0.1", port, 60)
        coord = subprocess.Popen([*CLI, "coordinator", *bus, "--run", run, "--taxis", str(args.taxis), "--minutes", str(args.minutes),
                                  "--hour", "19", "--policy", args.policy, "--forecast", "previous-hour", "--samples", str(args.samples), "--join-timeout", "600",
                                  "--json", str(result)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        procs.append(coord)
        if watched:
            http = free_tcp_port()
            watch = subprocess.Popen([*CLI, "watch", *bus, "--run", run, "--http", f"127.0.0.1:{http}", "--join-timeout", "600"],
                                     stderr=subprocess.PIPE, text=True)
            procs.append(watch)
            line = watch.stderr.readline()
            assert "surge watch: http://" in line, line
            threading.Thread(target=watch.stderr.read, daemon=True).start()
            wait_for_tcp("127.0.0.1", http, 60)
            if args.browser:
                driver = browser(f"http://127.0.0.1:{http}/", str(tmp / "profile"))
        procs.append(subprocess.Popen([*CLI, "agents", *bus, "--run", run, "--ids", f"0-{args.taxis - 1}"], stderr=subprocess.DEVNULL))
        coord.wait(3600)
        if driver is not None:
            frames = int(driver.find_element("tag name", "body").get_attribute("data-frame-index") or 0)
            shown = driver.find_element("id", "minute").text
    finally:
        if driver is not None:
            driver.quit()
        for p in procs:
            if p.poll() is None:
                p.terminate()
            p.wait(30)
    doc = json.loads(result.read_text())
    out = {"watched": watched, "minute_seconds": doc["minute_seconds"], "median_minute_s": doc["step_seconds"]["median"],
           "total_cost": doc["total_cost"], "decisions_sha256": doc["decisions_sha256"], "fallbacks": doc["fallbacks"]}
    if watched:
        out.update({"frames_pushed": frames, "page_minute_at_end": shown})
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--taxis", type=int, default=20)
    p.add_argument("--minutes", type=int, default=20)
    p.add_argument("--samples", type=int, default=200)
    p.add_argument("--policy", default="surge", help="every taxi's policy, with options as in surge evaluate")
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--no-browser", dest="browser", action="store_false", help="attach the watch server without a browser")
    p.add_argument("--json", required=True)
    args = p.parse_args()
    runs = []
    with tempfile.TemporaryDirectory(prefix="watch-cost-") as tmp:
        for r in range(args.rounds):
            for watched in ((False, True) if r % 2 == 0 else (True, False)):  # alternate which goes first
                runs.append({"round": r, **one_run(args, watched, Path(tmp))})
                print(json.dumps({k: v for k, v in runs[-1].items() if k != "minute_seconds"}), flush=True)
    pairs = [(next(x for x in runs if x["round"] == r and x["watched"])["median_minute_s"],
              next(x for x in runs if x["round"] == r and not x["watched"])["median_minute_s"]) for r in range(args.rounds)]
    diff = [w - u for w, u in pairs]
    what = "surge watch (server and a headless browser on this host)" if args.browser else "surge watch (server only)"
    doc = {"question": f"the fleet's median minute with and without {what} attached",
           "command": "python benchmarks/watch-cost/run.py " + " ".join(sys.argv[1:]),
           "date": dt.datetime.now().isoformat(timespec="seconds"),
           "machine": f"{platform.machine()}, {os.cpu_count()} vCPU",
           "settings": vars(args), "runs": runs,
           "paired_median_minute_s": [{"round": r, "watched": w, "unwatched": u} for r, (w, u) in enumerate(pairs)],
           "watched_minus_unwatched_s": {"each_round": diff, "mean": float(np.mean(diff))},
           "same_decisions": len({x["decisions_sha256"] for x in runs}) == 1}
    Path(args.json).write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
