"""A screenshot of ``surge watch --replay`` in headless Chromium (the docs' picture): minute MINUTE, its first wave deciding.

usage: watch_screenshot.py RESULTS.json OUT.png MINUTE [LAYER]

LAYER is the demand layer shown: forecast (default), realised or none.
Needs Debian's chromium and chromium-driver, and selenium.
"""

import subprocess
import sys
import tempfile
import time

from selenium import webdriver
from selenium.webdriver.chrome.service import Service

from bus.router import free_tcp_port, wait_for_tcp


def main() -> None:
    results, out, minute = sys.argv[1], sys.argv[2], int(sys.argv[3])
    layer = sys.argv[4] if len(sys.argv) > 4 else "forecast"
    port = free_tcp_port()
    server = subprocess.Popen([sys.executable, "-m", "coordinator.cli", "watch", "--replay", results, "--http", f"127.0.0.1:{port}"],
                              stderr=subprocess.PIPE, text=True)
    try:
        line = server.stderr.readline()
        if "surge watch: http://" not in line:
            raise SystemExit(line + server.stderr.read())
        wait_for_tcp("127.0.0.1", port, 30)
        with tempfile.TemporaryDirectory() as profile:
            options = webdriver.ChromeOptions()
            options.binary_location = "/usr/bin/chromium"
            for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                         "--disable-background-networking", "--disable-component-update", "--disable-sync",
                         "--window-size=1450,900", "--hide-scrollbars", f"--user-data-dir={profile}"):
                options.add_argument(flag)
            driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)
            try:
                driver.get(f"http://127.0.0.1:{port}/")
                deadline = time.monotonic() + 60
                while driver.find_element("id", "minute").text != str(min(minute, 1)):
                    if time.monotonic() > deadline:
                        raise SystemExit("the replay's first frame never came")
                    time.sleep(0.2)
                driver.find_element("css selector", f"input[name=layer][value={layer}]").click()
                for _ in range(minute - 1):
                    driver.find_element("id", "step").click()
                    time.sleep(0.3)
                driver.execute_script("send('seek ' + (Number(document.body.dataset.frameIndex) + 1))")
                time.sleep(1.0)
                driver.save_screenshot(out)
                print(f"minute {driver.find_element('id', 'minute').text}: wrote {out}")
            finally:
                driver.quit()
    finally:
        server.terminate()
        server.wait(10)


if __name__ == "__main__":
    main()
