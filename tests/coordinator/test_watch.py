"""``surge watch`` in a real browser: headless Chromium driven by Selenium, live on a secured run and in replay.

The live test starts a real TLS router, a coordinator, two agent processes
and ``surge watch`` holding the observer certificate; the page must show the
coordinator's minute and fleet.  The replay test plays the same run back
from the coordinator's results file and must end on its cost and service.
Both write a screenshot (``SURGE_WATCH_SCREENSHOTS=DIR`` keeps them).

Needs Debian's ``chromium`` and ``chromium-driver`` (``apt-get install -y
chromium chromium-driver``) and the ``test`` and ``watch`` extras.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from bus.router import free_tcp_port, wait_for_tcp
from city.errors import DataError

CLI = [sys.executable, "-m", "coordinator.cli"]
CHROMIUM, DRIVER = shutil.which("chromium"), shutil.which("chromedriver")
needs_browser = pytest.mark.skipif(CHROMIUM is None or DRIVER is None,
                                reason="the browser test needs Debian's chromium and chromium-driver "
                                       "(apt-get install -y chromium chromium-driver)")
MINUTES, TAXIS = 6, 2


def _screenshot_dir(tmp: Path) -> Path:
    out = Path(os.environ.get("SURGE_WATCH_SCREENSHOTS") or tmp)
    out.mkdir(parents=True, exist_ok=True)
    return out


@pytest.fixture(scope="module")
def browser(tmp_path_factory: pytest.TempPathFactory) -> Iterator:
    webdriver = pytest.importorskip("selenium.webdriver", reason="the browser test needs selenium (pip install 'surge[test]')")
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--window-size=1300,1000", f"--user-data-dir={tmp_path_factory.mktemp('chromium-profile')}"):
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service(DRIVER), options=options)
    try:
        yield driver
    finally:
        driver.quit()


def _watch(args: list[str], port: int) -> subprocess.Popen:
    """``surge watch`` serving on ``port``, once it says where."""
    proc = subprocess.Popen([*CLI, "watch", *args, "--http", f"127.0.0.1:{port}"], stderr=subprocess.PIPE, text=True)
    line = proc.stderr.readline()
    assert "surge watch: http://" in line, line + proc.stderr.read()
    threading.Thread(target=proc.stderr.read, daemon=True).start()  # keep its pipe drained
    wait_for_tcp("127.0.0.1", port, 30)
    return proc


def _text(driver, element_id: str) -> str:
    return driver.find_element("id", element_id).text


def _wait(predicate, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.2)


@pytest.fixture(scope="module")
def live_run(tmp_path_factory: pytest.TempPathFactory, browser, compiled_kernels) -> dict:
    """A secured 2-taxi run watched live; what the page showed, the coordinator's result and its log."""
    from bus.certs import make_certs

    tmp = tmp_path_factory.mktemp("watch-live")
    certs, result_path = tmp / "certs", tmp / "result.json"
    make_certs(certs, TAXIS)
    port, http = free_tcp_port(), free_tcp_port()
    endpoint = f"tls/127.0.0.1:{port}"
    bus = ["--connect", endpoint, "--certs", str(certs)]
    procs = [subprocess.Popen([*CLI, "router", "--certs", str(certs), "--listen", endpoint], stderr=subprocess.DEVNULL)]
    seen: list[tuple[str, str]] = []
    log: list[str] = []
    try:
        wait_for_tcp("127.0.0.1", port, 30)
        coord = subprocess.Popen([*CLI, "coordinator", *bus, "--run", "watched", "--taxis", str(TAXIS), "--minutes", str(MINUTES),
                                  "--forecast", "true-rate", "--samples", "30", "--deadline", "120", "--join-timeout", "300",
                                  "--minute-seconds", "2", "--json", str(result_path)],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        procs.append(coord)
        reader = threading.Thread(target=lambda: log.extend(iter(coord.stderr.readline, "")), daemon=True)
        reader.start()
        procs.append(_watch([*bus, "--run", "watched", "--join-timeout", "300"], http))
        browser.get(f"http://127.0.0.1:{http}/")
        procs.append(subprocess.Popen([*CLI, "agents", *bus, "--run", "watched", "--ids", f"0-{TAXIS - 1}"], stderr=subprocess.DEVNULL))
        deadline = time.monotonic() + 300
        while browser.find_element("tag name", "body").get_attribute("data-done") != "1":
            assert time.monotonic() < deadline, "the page never showed the end of the run"
            assert coord.poll() is None or coord.returncode == 0, "".join(log)
            seen.append((_text(browser, "minute"), _text(browser, "taxis")))
            time.sleep(0.3)
        coord.wait(60)
        reader.join(10)
        assert coord.returncode == 0, "".join(log)
        shot = _screenshot_dir(tmp) / "watch-live.png"
        browser.save_screenshot(str(shot))
        final = {k: _text(browser, k) for k in ("minute", "minutes", "taxis", "cost", "served", "waiting", "fallbacks", "waves")}
        mode = _text(browser, "mode")
    finally:
        for p in procs:
            if p.poll() is None:
                p.terminate()
            p.wait(10)
    return {"seen": seen, "final": final, "mode": mode, "result": json.loads(result_path.read_text()), "log": log,
            "result_path": result_path, "shot": shot}


@needs_browser
def test_the_live_page_shows_the_coordinators_minute_and_fleet(live_run: dict) -> None:
    result, final = live_run["result"], live_run["final"]
    assert live_run["mode"] == "live"
    assert final["minute"] == str(result["minutes"]) == str(MINUTES) and final["minutes"] == str(MINUTES)
    assert final["taxis"] == str(result["taxis"]) == str(TAXIS)
    assert final["fallbacks"] == str(result["fallbacks"])
    # the coordinator logs "minute k/M" as it finishes minute k; the page followed it minute by minute
    logged = [int(line.split("minute ")[1].split("/")[0]) for line in live_run["log"] if ": minute " in line]
    assert logged == list(range(1, MINUTES + 1))
    shown = [int(m) for m, _ in live_run["seen"] if m.isdigit()]
    assert len(set(shown) & set(range(1, MINUTES))) >= 2, shown  # live: minutes in progress, not only the end
    assert shown == sorted(shown)
    assert live_run["shot"].stat().st_size > 10_000


@needs_browser
def test_a_replay_plays_the_run_back_to_its_cost(live_run: dict, browser, tmp_path: Path) -> None:
    result = live_run["result"]
    http = free_tcp_port()
    proc = _watch(["--replay", str(live_run["result_path"])], http)
    try:
        browser.get(f"http://127.0.0.1:{http}/")
        _wait(lambda: _text(browser, "minute") == "1", 60, "the replay's first frame")
        assert _text(browser, "mode") == "replay" and _text(browser, "taxis") == str(TAXIS)
        body = browser.find_element("tag name", "body")
        shown = []
        while body.get_attribute("data-done") != "1" and len(shown) <= MINUTES:
            before = body.get_attribute("data-frame-index")
            browser.find_element("id", "step").click()  # on to the end of the next minute, its controls committed
            _wait(lambda before=before: body.get_attribute("data-frame-index") != before, 10, f"the step after frame {before}")
            shown.append(int(_text(browser, "minute")))
        assert shown == [*range(1, MINUTES + 1), MINUTES]  # minute 0 opens with its first wave deciding
        assert _text(browser, "cost") == str(result["total_cost"]) and _text(browser, "served") == str(result["served"])
        browser.find_element("id", "back").click()
        _wait(lambda: _text(browser, "minute") == str(MINUTES), 10, "a step back")
        browser.find_element("id", "play").click()  # plays on from there to the end
        _wait(lambda: body.get_attribute("data-done") == "1", 30, "play to the end")
        shot = _screenshot_dir(tmp_path) / "watch-replay.png"
        browser.save_screenshot(str(shot))
        assert shot.stat().st_size > 10_000
        drawn = browser.execute_script(
            "const c = document.getElementById('map'); return Array.from(c.getContext('2d').getImageData(0, 0, c.width, c.height).data);")
        colours = np.asarray(drawn, dtype=np.uint8).reshape(-1, 4)[:, :3]
        assert len(np.unique(colours, axis=0)) > 20  # streets, demand, taxis: the map is drawn, not blank
    finally:
        proc.terminate()
        proc.wait(10)


def test_a_replay_of_a_file_that_is_not_a_run_is_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "r.json"
    bad.write_text(json.dumps({"taxis": 2, "minutes": 3}))
    proc = subprocess.run([*CLI, "watch", "--replay", str(bad)], capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 2
    expected = f"surge: error: {bad}: no key 'controls': not a run's results (`surge fleet --json`, `surge coordinator --json`, `surge demo`)"
    assert proc.stderr.strip().splitlines() == [expected]


@pytest.mark.usefixtures("compiled_kernels")
def test_a_replay_rebuilds_every_minute_of_the_run_from_its_controls(tmp_path: Path) -> None:
    """Frames from an in-process run's controls: each minute's fleet as the simulator had it, and its cost and service."""
    from dataclasses import asdict

    from city.episode import run_episode
    from city.sim import FleetSim, decisions_hash
    from coordinator.run_config import FleetConfig
    from coordinator.watch.replay import build_replay

    cfg = FleetConfig(taxis=3, minutes=5, options={"forecast": "true-rate", "samples": 30})
    scen, requests, start, context = cfg.instance()
    res = run_episode(scen.city, cfg.make_policy(scen.city), requests, start, context)
    doc = {"taxis": 3, "minutes": 5, "config": asdict(cfg), "controls": res.controls.tolist(), "total_cost": res.total_cost,
           "decisions_sha256": res.decisions_sha256}
    path = tmp_path / "run.json"
    path.write_text(json.dumps(doc))
    replay = build_replay(path, cfg)
    frames = [json.loads(replay.frames[i]) for i in replay.minute_ends]
    sim, costs = FleetSim(scen.city, requests, start), []
    for t, frame in enumerate(frames[:-1]):
        obs = sim.observe()
        assert frame["minute"] == t + 1 and frame["pos"] == obs.pos.tolist() and frame["waiting"] == obs.req_index.size
        assert frame["taxis"] == 3 and len(frame["forecast"]) == scen.city.n_sectors
        # the cost and pickups of the minutes before, as the states on the bus tell them
        assert frame["cost"] == sum(costs) and frame["cost_to"] == t
        assert frame["served"] == int((sim.state.picked_at >= 0).sum())
        costs.append(sim.step(res.controls[t]))
    assert frames[-1]["done"] and frames[-1]["cost"] == res.total_cost and frames[-1]["served"] == res.served
    assert replay.map["events"] and len(replay.map["xy"]) == 2 * scen.city.n_nodes
    # a file whose controls were altered is refused in one line naming it
    doc["controls"][0][0] = -1 if doc["controls"][0][0] >= 0 else int(scen.city.neighbors(int(start[0]))[0])
    path.write_text(json.dumps(doc))
    with pytest.raises(DataError, match=rf"^{path}: key 'controls' does not hash to its 'decisions_sha256': the file was altered$"):
        build_replay(path, cfg)
    assert decisions_hash(np.asarray(doc["controls"])) != res.decisions_sha256
