"""Who may use the console (issue 26, item 1), tried as an attacker would, against a real ``hrc console``
process and in Debian's headless Chromium.

One console serves every test of this module (no simulated robot, no ticks), so that nothing but a
message some test got through could change its log: each test checks that the log's bytes did not
change. Skipped with the reason when playwright or Chromium is missing (failed under
HRC_REQUIRE_BROWSER=1, as CI sets it).
"""

from __future__ import annotations

import http.client
import http.server
import json
import threading
from collections.abc import Iterator
from typing import Any

import pytest
from console_harness import ConsoleProcess, browser_or_skip, chromium, compiled_workshop, connected_page

pytestmark = pytest.mark.filterwarnings("ignore::ResourceWarning")


@pytest.fixture(scope="module")
def console(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ConsoleProcess]:
    browser_or_skip()
    out = compiled_workshop(tmp_path_factory.mktemp("ws"))
    proc = ConsoleProcess(out, out / "run.jsonl", "--tick", "0")
    try:
        yield proc
    finally:
        proc.stop()


@pytest.fixture
def untouched(console: ConsoleProcess) -> Iterator[None]:
    """The test must leave the run's log exactly as it found it (and the run's state too)."""
    before, state = console.log.read_bytes(), console.state()
    yield
    assert console.log.read_bytes() == before
    after = console.state()
    assert (after["seq"], after["hseq"], after["log_total"]) == (state["seq"], state["hseq"], state["log_total"])


def _status(console: ConsoleProcess, path: str, headers: dict[str, str]) -> tuple[int, str]:
    port = int(console.base.rsplit(":", 1)[1].strip("/"))
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    try:
        conn.putrequest("GET", path, skip_host=True, skip_accept_encoding=True)
        for name, value in headers.items():
            conn.putheader(name, value)
        conn.endheaders()
        response = conn.getresponse()
        return response.status, response.read().decode()
    finally:
        conn.close()


def _host(console: ConsoleProcess) -> str:
    return console.base.removeprefix("http://").strip("/")


def _ws_status(console: ConsoleProcess, path: str, headers: dict[str, str]) -> int:
    """The HTTP status a websocket upgrade gets (101: accepted)."""
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    try:
        with connect(console.ws + path, open_timeout=10, close_timeout=2, additional_headers=headers):
            return 101
    except InvalidStatus as err:
        return err.response.status_code


def test_a_client_without_the_secret_gets_nothing(console: ConsoleProcess, untouched: None) -> None:
    host = {"Host": _host(console)}
    wrong = "x" * 43
    for path in ("/", "/state", "/log", "/static/console.js", "/static/console.css", "/nowhere"):
        for headers in (host, {**host, "Authorization": f"Bearer {wrong}"},
                        {**host, "Cookie": f"hrc_console_{_host(console).split(':')[1]}={wrong}"},
                        {**host, "Authorization": f"Bearer {console.robot_token}"}):
            status, body = _status(console, path, headers)
            assert status == 401 and body.startswith("refused:") and body.count("\n") == 1, (path, headers, body)
    assert _status(console, f"/?token={wrong}", host)[0] == 401
    # the page's secret opens every route but the robot's, the robot's secret only the robot's
    assert _status(console, "/state", {**host, "Authorization": f"Bearer {console.token}"})[0] == 200
    assert _ws_status(console, "ws", {}) == 401
    assert _ws_status(console, "ws", {"Authorization": f"Bearer {wrong}"}) == 401
    assert _ws_status(console, "ws", console.robot_headers()) == 401
    assert _ws_status(console, "robot", {}) == 401
    assert _ws_status(console, "robot", console.page_headers()) == 401  # a page cannot take the robot's slot
    # the first load trades the token for an HttpOnly, SameSite=Strict cookie and drops it from the address
    port = int(_host(console).split(":")[1])
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    conn.request("GET", f"/?token={console.token}")
    response = conn.getresponse()
    assert response.status == 303 and response.getheader("Location") == "/"
    cookie = response.getheader("Set-Cookie") or ""
    assert cookie.startswith(f"hrc_console_{port}={console.token};") and "HttpOnly" in cookie
    assert "SameSite=Strict" in cookie
    conn.close()
    # in the browser: without the secret, the page is not even served
    with chromium() as ctx:
        page = ctx.new_page()
        response = page.goto(console.base)
        assert response is not None and response.status == 401
        assert page.evaluate("() => typeof window.hrcConsole") == "undefined"


def test_a_wrong_host_gets_400_even_with_the_secret(console: ConsoleProcess, untouched: None) -> None:
    port = _host(console).split(":")[1]
    for host in (f"rebind.test:{port}", "127.0.0.1", f"127.0.0.1:{int(port) + 1}", f"evil.127.0.0.1.nip.io:{port}",
                 ""):
        status, body = _status(console, "/state", {"Host": host, "Authorization": f"Bearer {console.token}"})
        assert status == 400 and "unknown Host" in body, (host, status, body)
    assert _status(console, "/state", {"Authorization": f"Bearer {console.token}"})[0] == 400  # no Host at all
    # DNS rebinding in Chromium: a name of the attacker's that now resolves to 127.0.0.1
    flags = ("--host-resolver-rules=MAP rebind.test 127.0.0.1", "--proxy-bypass-list=rebind.test")
    with chromium(extra_flags=flags) as ctx:
        page = ctx.new_page()
        response = page.goto(console.url.replace("127.0.0.1", "rebind.test"))
        assert response is not None and response.status == 400
        assert page.evaluate("() => fetch('/state').then(r => r.status)") == 400
        assert page.evaluate("() => fetch('/log').then(r => r.status)") == 400


_ATTACK_PAGE = """<!doctype html><meta charset="utf-8"><title>elsewhere</title><script>
window.result = (async () => {
  const target = TARGET, press = PRESS, out = {sockets: {}, reads: {}};
  const open = (path) => new Promise((done) => {
    const got = [];
    let opened = false;
    const ws = new WebSocket(target.replace("http://", "ws://") + path);
    ws.onopen = () => {
      opened = true; ws.send(JSON.stringify(press)); ws.send(JSON.stringify({type: "ack", ...press}));
    };
    ws.onmessage = (e) => got.push(String(e.data));
    ws.onclose = (e) => done({opened, got, code: e.code});
    setTimeout(() => { try { ws.close(); } catch (e) {} done({opened, got, timeout: true}); }, 5000);
  });
  out.sockets.ws = await open("ws");
  out.sockets.robot = await open("robot");
  for (const path of ["state", "log", ""]) {
    try {
      const r = await fetch(target + path, {credentials: "include"});
      out.reads[path] = "status " + r.status + " " + (await r.text());
    } catch (e) { out.reads[path] = "failed: " + e.name; }
  }
  try {
    const r = await fetch(target + "state", {credentials: "include", mode: "no-cors"});
    out.reads.opaque = r.type + " " + (await r.text()).length;
  } catch (e) { out.reads.opaque = "failed: " + e.name; }
  return out;
})();
</script>"""


class _AttackSite:
    """A second local HTTP server, on another port: the other site whose page the person opens."""

    def __init__(self, page: str) -> None:
        body = page.encode()

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self) -> None:  # noqa: N802 - http.server's name
                self.send_response(200)
                self.send_header("Content-Type", "text/html; charset=utf-8")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            def log_message(self, *args: Any) -> None:
                pass

        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.port = self.server.server_address[1]
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()
        self.thread.join(timeout=10)


def test_a_page_from_another_origin_can_neither_read_nor_press(console: ConsoleProcess, untouched: None) -> None:
    option = console.state()["options"][0]
    press = {"type": "press", "hseq": console.state()["hseq"], **option}
    page_text = _ATTACK_PAGE.replace("TARGET", json.dumps(console.base)).replace("PRESS", json.dumps(press))
    site = _AttackSite(page_text)
    try:
        with chromium() as ctx:
            # the person has the console open in this browser: its cookie is there to be (mis)used
            own = connected_page(ctx, console.url)
            cookies = {c["name"]: c for c in ctx.cookies()}
            port = _host(console).split(":")[1]
            assert cookies[f"hrc_console_{port}"]["httpOnly"] and cookies[f"hrc_console_{port}"]["sameSite"] == "Strict"
            # another port of 127.0.0.1 is the same *site* (the cookie goes along), and localhost another one
            for origin in (f"http://127.0.0.1:{site.port}/", f"http://localhost:{site.port}/"):
                page = ctx.new_page()
                page.goto(origin)
                result = page.evaluate("() => window.result")
                for path, sock in result["sockets"].items():
                    assert not sock["opened"] and sock["got"] == [], (origin, path, sock)
                for path, read in result["reads"].items():
                    assert not read.startswith("status 200"), (origin, path, read)
                    assert console.token not in read and "options" not in read, (origin, path, read)
                page.close()
            # the person's own page still works
            assert own.evaluate("() => window.hrcConsole.connected")
    finally:
        site.close()
