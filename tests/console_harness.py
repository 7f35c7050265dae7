"""Helpers of the console's tests: a compiled workshop, an `hrc console` process, a headless Chromium.

The browser is Debian's ``/usr/bin/chromium`` driven by playwright for Python (no browser download),
started with the flags that keep it offline and quiet, and behind a proxy that does not exist, so
that anything the page asked of a host other than this machine's loopback would fail (and is also
recorded by `record_requests`). Every wait here is bounded.
"""

from __future__ import annotations

import json
import os
import queue
import shutil
import subprocess
import sys
import threading
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
WORKSHOP = ROOT / "tasks" / "cube_stacking.yaml"
CHROMIUM = os.environ.get("HRC_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--proxy-server=http://127.0.0.1:9"]  # loopback bypasses proxies: everything else fails
START_TIMEOUT = 60.0  # s for `hrc console` to listen (it plans the map's paths first)


def compiled_workshop(out: Path) -> Path:
    """The bundled workshop compiled into a new folder below `out` (one process), for a console to serve."""
    from conftest import compiled_folder

    return compiled_folder(out / "ws", WORKSHOP, "--jobs", "1")


def browser_or_skip() -> Any:
    """playwright's sync API, or skip (fail when HRC_REQUIRE_BROWSER=1, as in CI) naming what is missing."""
    missing = None
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        missing = "playwright for Python is not installed (pip install -e '.[test]')"
    if missing is None and not (os.path.exists(CHROMIUM) or shutil.which(CHROMIUM)):
        missing = f"no Chromium at {CHROMIUM} (as root: apt-get install chromium; `make test` does it)"
    if missing:
        if os.environ.get("HRC_REQUIRE_BROWSER") == "1":
            pytest.fail(f"browser tests required (HRC_REQUIRE_BROWSER=1) but {missing}")
        pytest.skip(f"browser tests skipped: {missing}")
    return sync_playwright


@contextmanager
def chromium(viewport: tuple[int, int] = (1400, 1050), extra_flags: tuple[str, ...] = ()) -> Iterator[Any]:
    """A browser context of a headless Chromium; its default timeout is 15 s."""
    sync_playwright = browser_or_skip()
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=[*CHROMIUM_FLAGS, *extra_flags],
                                    timeout=30_000)
        try:
            context = browser.new_context(viewport={"width": viewport[0], "height": viewport[1]})
            context.set_default_timeout(15_000)
            yield context
        finally:
            browser.close()


class ConsoleProcess:
    """``python -m hrc console OUT_DIR --port 0 ...`` in a subprocess; once it listens, `url` (what it
    printed to open, with the page's token), `base` (the same without the token), `token` and
    `robot_token` (from ``--robot-token-file`` beside the log). `log_option` False: no ``--log`` given
    (a test that resumes gives ``--resume``). `nofile`: the process's open-file limit (default: as inherited)."""

    def __init__(self, out_dir: Path, log: Path, *args: str, log_option: bool = True,
                 nofile: int | None = None) -> None:
        env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        self.log = log
        self._stderr: str | None = None
        robot_file = log.with_name(log.name + ".robot-token")
        logging = ["--log", str(log)] if log_option else []
        self.proc = subprocess.Popen([sys.executable, "-m", "hrc", "console", str(out_dir), "--port", "0",
                                      *logging, "--robot-token-file", str(robot_file), *args], cwd=ROOT, env=env,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     preexec_fn=None if nofile is None else lambda: _limit_files(nofile))
        lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=lambda: [lines.put(x) for x in self.proc.stdout or ()], daemon=True).start()
        try:
            first = lines.get(timeout=START_TIMEOUT)
        except queue.Empty:
            self.stop()
            raise AssertionError(f"hrc console did not start within {START_TIMEOUT} s") from None
        if "http://" not in first:
            self.stop()
            raise AssertionError(f"hrc console: {first} {self.stderr()}")
        self.url = first.split()[2]
        self.lines = lines  # what it printed after the first line (a team's pages, the robot's address)
        self.base, _, self.token = self.url.partition("?token=")
        self.ws = self.base.replace("http://", "ws://")
        self.robot_token = robot_file.read_text().strip()

    def get(self, path: str, token: str | None = None) -> bytes:
        """GET `path` with the page's token (or `token`) as a bearer credential."""
        request = urllib.request.Request(self.base + path.lstrip("/"),
                                         headers={"Authorization": f"Bearer {token or self.token}"})
        with urllib.request.urlopen(request, timeout=10) as r:
            return r.read()

    def page_headers(self) -> dict[str, str]:
        return {"Authorization": f"Bearer {self.token}"}

    def robot_headers(self) -> dict[str, str]:
        return {"Authorization": f"Bearer {self.robot_token}"}

    def state(self) -> dict[str, Any]:
        return json.loads(self.get("state"))

    def log_lines(self) -> list[dict[str, Any]]:
        """The log's messages and answers after its header, decoded, in order: in, out, in, out, ..."""
        from hrc.dispatch.logfile import read_log

        return [json.loads(x) for m in read_log(self.log).messages for x in (m.data, m.answer)]

    def stderr(self) -> str:
        """What the process wrote on stderr (once it has ended; kept after `stop`)."""
        if self._stderr is None and self.proc.poll() is not None and self.proc.stderr and not self.proc.stderr.closed:
            self._stderr = self.proc.stderr.read()
        return self._stderr or ""

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=10)
        self.stderr()
        for f in (self.proc.stdout, self.proc.stderr):
            if f:
                f.close()


def _limit_files(n: int) -> None:
    """In the console's process, before it starts: at most `n` open files (``RLIMIT_NOFILE``'s soft limit)."""
    import resource

    resource.setrlimit(resource.RLIMIT_NOFILE, (n, resource.getrlimit(resource.RLIMIT_NOFILE)[1]))


def connected_page(ctx: Any, url: str) -> Any:
    """A new page of browser context `ctx` at the console's `url`, once its websocket is connected."""
    page = ctx.new_page()
    page.goto(url)
    page.wait_for_function("() => window.hrcConsole && window.hrcConsole.connected", timeout=15_000)
    return page


def record_requests(page: Any) -> list[str]:
    """Every URL the page asks for (its websockets included), appended as they happen."""
    seen: list[str] = []
    page.on("request", lambda r: seen.append(r.url))
    page.on("websocket", lambda ws: seen.append(ws.url))
    return seen


def offline_main(out_dir: str, log: str) -> None:
    """Run in a network namespace with nothing but loopback (see the test): start the console, load the
    page in Chromium, print one JSON line of what the page drew."""
    server = ConsoleProcess(Path(out_dir), Path(log), "--simulate-robot")
    try:
        with chromium() as ctx:
            page = ctx.new_page()
            requests = record_requests(page)
            page.goto(server.url)
            page.wait_for_function("() => window.hrcConsole && window.hrcConsole.connected "
                                   "&& document.querySelectorAll('#map polygon').length > 0", timeout=15_000)
            drawn = page.evaluate("""() => ({buttons: document.querySelectorAll('#buttons button.act').length,
                obstacles: document.querySelectorAll('#map polygon').length,
                bars: document.querySelectorAll('#gantt rect').length,
                link: document.getElementById('link').textContent,
                css: getComputedStyle(document.body).backgroundColor})""")
            print(json.dumps({"drawn": drawn, "requests": requests}), flush=True)
    finally:
        server.stop()
