"""What an RTI user waits for in ``rig view``: the URL, the first relit frame, each light move.

``python -m bench.light_view -o DIR [--capture CAPTURE] [--moves 20]`` runs ``rig view CAPTURE``
(default: the bundled lion) as a user does, opens the printed URL in headless Chromium (WebGL2
on its software renderer, as the tests use it) and times:

- ``to_url_s``: from starting the command to the URL printed (import, reading the panoramas);
- ``url_to_light_frame_s``: from the URL to the first frame of the directional light drawn
  (the server writing the HSH/PTM planes, the page loading them, compiling the shader);
- ``url_to_session_s``: from the URL to the panorama session ready (the best mode's fit);
- ``light_move_ms``: median and maximum over ``--moves`` light moves of the time from the move
  to the frame drawn (``gl.finish``: the GPU's time included);
- ``peak_rss_mb``: the server process's peak resident memory (``wait4``).

Writes ``light_view.json`` and prints it. Not a test: nothing is asserted about time.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from core.sample_data import rti_capture_path

__all__ = ["main", "time_light_view"]

CHROMIUM_ARGS = [
    "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
]  # fmt: skip


def time_light_view(capture: Path, *, moves: int = 20, timeout_s: float = 1800.0) -> dict[str, Any]:
    """Time ``rig view capture`` in Chromium (see the module's docstring)."""
    from playwright.sync_api import sync_playwright

    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        raise SystemExit("bench.light_view needs Chromium (apt-get install chromium)")
    started = time.perf_counter()
    server = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "view", str(capture), "--port", "0"],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
    )  # fmt: skip
    result: dict[str, Any] = {"capture": str(capture)}
    try:
        assert server.stdout is not None
        url = None
        for line in server.stdout:
            found = re.search(r"open (http\S+)", line)
            if found:
                url = found.group(1)
                break
        if url is None:
            raise SystemExit(f"rig view {capture} ended without printing a URL")
        at_url = time.perf_counter()
        result["to_url_s"] = round(at_url - started, 2)
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.goto(url)
            timeout = int(timeout_s * 1000)
            page.wait_for_function(
                "() => Number(document.body.dataset.lightFrame || 0) > 0", timeout=timeout
            )
            result["url_to_light_frame_s"] = round(time.perf_counter() - at_url, 2)
            times = []
            for k in range(moves):
                angle = 2 * math.pi * k / moves
                times.append(
                    page.evaluate(
                        """([x, y]) => new Promise((done) => {
                            const before = Number(document.body.dataset.lightFrame);
                            const start = performance.now();
                            lightView.setLight(x, y);
                            const wait = () => Number(document.body.dataset.lightFrame) > before
                                ? done(performance.now() - start) : requestAnimationFrame(wait);
                            wait();
                        })""",
                        [0.6 * math.cos(angle), 0.6 * math.sin(angle)],
                    )
                )
            times.sort()
            result["light_move_ms"] = {
                "median": round(times[len(times) // 2], 1),
                "max": round(times[-1], 1),
            }
            page.wait_for_function("() => !document.body.classList.contains('preparing')",
                                   timeout=timeout)  # fmt: skip
            result["url_to_session_s"] = round(time.perf_counter() - at_url, 2)
            result["light_status"] = page.inner_text("#light-status")
            browser.close()
    finally:
        server.terminate()
        _, status, usage = os.wait4(server.pid, 0)
        result["peak_rss_mb"] = round(usage.ru_maxrss / 1024, 1)
        result["server_exit"] = os.waitstatus_to_exitcode(status)
    return result


def main(argv: list[str] | None = None) -> int:
    """``python -m bench.light_view``."""
    parser = argparse.ArgumentParser(prog="python -m bench.light_view", description=__doc__)
    parser.add_argument("-o", "--output", type=Path, required=True)
    parser.add_argument("--capture", type=Path, default=None, help="default: the bundled lion")
    parser.add_argument("--moves", type=int, default=20)
    args = parser.parse_args(argv)
    result = time_light_view(args.capture or rti_capture_path(), moves=args.moves)
    args.output.mkdir(parents=True, exist_ok=True)
    (args.output / "light_view.json").write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
