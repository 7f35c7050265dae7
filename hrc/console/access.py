"""Who may use the console: a secret per run for the page, another for the robot controller, and only
this server's own address and origin.

The console commands a robot, so it trusts nobody by default (issue 26). Three checks run on every
HTTP request and every websocket upgrade, before any route sees it (`AccessGuard`, an ASGI middleware):

1. **Host** must name this server (`allowed_hosts`): a page on another site whose name an attacker
   made resolve to 127.0.0.1 (DNS rebinding) sends its own name as ``Host`` and gets 400.
2. **Origin**, when the client sends one (browsers always do on websockets and cross-origin requests),
   must be this server's own origin (``http://`` + the request's Host); and ``Sec-Fetch-Site``, when
   sent, must say ``same-origin`` or ``none`` (a typed URL). A page served from anywhere else, another
   port of 127.0.0.1 included, gets 403: it can neither read the run nor press.
3. **A credential**: the page's secret (``?token=`` on the first load of ``/``, which sets an
   HttpOnly, SameSite=Strict cookie and redirects to ``/`` so that the token leaves the address bar;
   then the cookie, or ``Authorization: Bearer TOKEN`` for a script) on every route but ``/robot``;
   the robot's own secret (``Authorization: Bearer ROBOT_TOKEN``, which a page's script cannot set on
   a websocket) on ``/robot``. Missing or wrong: 401. Tokens are compared in constant time
   (`hmac.compare_digest`).

A team (issue 37) adds a secret per person (`Credentials.people`): it opens that person's page (``/`` and
``/ws`` with ``?person=ID``; its first load sets a cookie of that person's, so that two people's pages live
in one browser) and the read-only routes, and no other person's page nor the shared view; the page's
secret (the engineer's) opens every page.

Secrets come from `secrets.token_urlsafe` (256 bits), one per run, or from a token file
(`load_or_create_token`: read when it exists, else written, mode 0600), so that a robot controller can
be given its token before the console starts.

Cookies are not isolated by port: a page served by *another program* on this machine could receive
the cookie if the browser visits it. The Origin check still refuses that page's requests here; what it
cannot stop is that program replaying the cookie from outside a browser, which needs code running on
this machine already (docs/console.md, "Access").
"""

from __future__ import annotations

import hmac
import ipaddress
import os
import re
import secrets
import socket
import stat
from collections.abc import Awaitable, Callable, Iterable, MutableMapping
from dataclasses import dataclass
from http.cookies import SimpleCookie
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs

from hrc.errors import InputError

__all__ = ["ROBOT_PATH", "TOKEN_PATTERN", "AccessGuard", "Credentials", "allowed_hosts", "is_loopback",
           "load_or_create_token", "new_token"]

ROBOT_PATH = "/robot"
TOKEN_PATTERN = re.compile(r"[A-Za-z0-9_-]{32,256}")
"""What a token looks like: URL-safe base64, at least 32 characters (192 bits)."""
PERSON_PATTERN = re.compile(r"[A-Za-z0-9_.-]{1,64}")
"""A person's id as the first load's ``&person=`` may carry it on to ``/?person=`` (issue 37)."""

Scope = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[MutableMapping[str, Any]]]
Send = Callable[[MutableMapping[str, Any]], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]


def new_token() -> str:
    """A fresh secret: 32 random bytes as URL-safe base64 (43 characters)."""
    return secrets.token_urlsafe(32)


def load_or_create_token(path: str | os.PathLike[str]) -> str:
    """The token in `path` if the file exists, else a new one written there (mode 0600, never over a file).

    Raises `InputError` when the file is not a token (one line of `TOKEN_PATTERN`) or when others than
    its owner may read it (as ssh refuses such a key: chmod 600 it).
    """
    file = Path(path)
    try:
        fd = os.open(file, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        return _read_token(file)
    except OSError as err:
        raise InputError(str(file), "", f"cannot create the token file ({err.strerror or err})") from err
    token = new_token()
    with os.fdopen(fd, "w", encoding="ascii") as fh:
        fh.write(token + "\n")
        fh.flush()
        os.fsync(fh.fileno())
    return token


def _read_token(file: Path) -> str:
    try:
        info = file.stat()
        if not stat.S_ISREG(info.st_mode):
            raise InputError(str(file), "", "the token file must be a regular file")
        if info.st_mode & 0o077:
            raise InputError(str(file), "", f"others may read this token file (mode {info.st_mode & 0o777:o}); "
                                            "chmod 600 it")
        text = file.read_text(encoding="ascii").strip()
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(str(file), "", f"cannot read the token file ({err})") from err
    if not TOKEN_PATTERN.fullmatch(text):
        raise InputError(str(file), "", "not a token (one line of 32 to 256 letters, digits, '-' or '_')")
    return text


def is_loopback(host: str) -> bool:
    """Whether `host` (an address or ``localhost``) can only be reached from this machine."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def allowed_hosts(host: str, port: int) -> frozenset[str]:
    """The ``Host`` header values that name a server listening on `host`:`port`.

    Loopback: 127.0.0.1, localhost and [::1]. A wildcard address (0.0.0.0, ::, with ``--allow-remote``)
    adds this machine's name and its addresses; any other address, itself.

    >>> sorted(allowed_hosts("127.0.0.1", 8765))
    ['127.0.0.1:8765', '[::1]:8765', 'localhost:8765']
    """
    names: set[str] = {"127.0.0.1", "localhost", "::1"}
    if not is_loopback(host):
        names = {host.strip("[]")}
        if host in ("0.0.0.0", "::", ""):
            names |= {"127.0.0.1", "localhost", "::1", socket.gethostname(), socket.getfqdn()}
            try:
                names |= {str(info[4][0]) for info in socket.getaddrinfo(socket.gethostname(), None)}
            except OSError:
                pass
    out = {f"[{n}]:{port}" if ":" in n else f"{n}:{port}" for n in names}
    if port == 80:  # a browser leaves the default port out of Host
        out |= {f"[{n}]" if ":" in n else n for n in names}
    return frozenset(out)


@dataclass(frozen=True, slots=True)
class Credentials:
    """The run's secrets: `page` (the person's pages and scripts; a team's engineer: every page) and
    `robot` (``/robot`` only); `people`: a team's (person id, their own page's secret) pairs (issue 37)."""

    page: str
    robot: str
    people: tuple[tuple[str, str], ...] = ()

    def __post_init__(self) -> None:
        for name, value in (("page", self.page), ("robot", self.robot), *self.people):
            if not TOKEN_PATTERN.fullmatch(value):
                raise ValueError(f"the {name} token is not a token")
        tokens = [self.page, self.robot, *(t for _, t in self.people)]
        if any(hmac.compare_digest(a, b) for k, a in enumerate(tokens) for b in tokens[k + 1:]):
            raise ValueError("the page, the robot and each person must have different tokens")
        if not all(PERSON_PATTERN.fullmatch(p) for p, _ in self.people):
            raise ValueError("a person's id cannot name a page")

    def person(self, token: str | None) -> str | None:
        """The person whose own secret `token` is, or None."""
        return next((p for p, t in self.people if _same(token, t)), None)

    @classmethod
    def generate(cls) -> Credentials:
        return cls(new_token(), new_token())


def _same(given: str | None, expected: str) -> bool:
    """Constant-time equality (an absent or non-ASCII value is simply wrong)."""
    if given is None:
        return False
    return hmac.compare_digest(given.encode("utf-8", "surrogateescape"), expected.encode("ascii"))


class AccessGuard:
    """ASGI middleware in front of the console's app: the three checks of the module docstring.

    Until `listen` has named the address served, every request is refused. The page's cookie is named
    for the port (cookies are shared by every port of a host). Refusals are plain text, one line;
    a refused websocket gets the same status through the ASGI ``websocket.http.response`` extension
    (or 403 where the server lacks it). `denied` counts the refusals (shown to the engineer).
    """

    def __init__(self, app: ASGIApp, credentials: Credentials) -> None:
        self.app = app
        self.credentials = credentials
        self.hosts: frozenset[str] = frozenset()
        self.cookie = "hrc_console"
        self.denied = 0
        self.on_refused_upgrade: Callable[[], None] | None = None  # after each websocket refused
        self.on_request: Callable[[Any, bool], None] | None = None  # (client, an admitted websocket?)

    def listen(self, host: str, port: int, hosts: Iterable[str] | None = None) -> None:
        """Serve `host`:`port` (its `allowed_hosts`, or `hosts`)."""
        self.hosts = frozenset(h.lower() for h in (allowed_hosts(host, port) if hosts is None else hosts))
        self.cookie = f"hrc_console_{port}"

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)  # lifespan
            return
        if self.on_request is not None:  # a whole request came: the connection is no longer idle
            self.on_request(scope.get("client"), False)
        refusal = _bounded(scope)
        if refusal is not None:  # before anything reads them: no 500 for a long or many-fielded query
            self.denied += 1
            await _refuse(scope, receive, send, *refusal)
            self._refused_upgrade(scope)
            return
        headers = _headers(scope)
        first_load = scope["type"] == "http" and scope["path"] == "/" and _query_token(scope) is not None
        refusal = self._check(scope, headers, first_load)
        if refusal is None and first_load:  # the URL printed at start: trade the token for a cookie, drop it
            await self._redirect_with_cookie(send, _query_value(scope, "person"), _query_token(scope) or "")
            return
        if refusal is not None:
            self.denied += 1
            await _refuse(scope, receive, send, *refusal)
            self._refused_upgrade(scope)
            return
        if scope["type"] == "websocket" and self.on_request is not None:  # an admitted websocket: kept
            self.on_request(scope.get("client"), True)
        await self.app(scope, receive, send)

    def _refused_upgrade(self, scope: Scope) -> None:
        if scope["type"] == "websocket" and self.on_refused_upgrade is not None:
            self.on_refused_upgrade()

    def _check(self, scope: Scope, headers: dict[str, str], first_load: bool) -> tuple[int, str] | None:
        host = headers.get("host", "").lower()
        if host not in self.hosts:
            return 400, f"refused: unknown Host {host[:80]!r} (this console answers only to its own address)"
        origin = headers.get("origin")
        if origin is not None and origin.lower() != f"http://{host}":
            return 403, f"refused: a page from {origin[:80]!r} may not use this console"
        if headers.get("sec-fetch-site", "same-origin") not in ("same-origin", "none"):
            return 403, "refused: a request made by another site's page"
        if scope["type"] == "websocket" and scope["path"] == ROBOT_PATH:
            if not _same(_bearer(headers), self.credentials.robot):
                return 401, "refused: /robot needs the robot's token (Authorization: Bearer ROBOT_TOKEN)"
            return None
        given = _query_token(scope) if first_load else _bearer(headers) or _cookie(headers, self.cookie)
        if _same(given, self.credentials.page):
            return None
        if self.credentials.people:  # a team's person's own secret (issue 37): their page only
            return self._person_check(scope, headers, first_load)
        return 401, "refused: open the address `hrc console` printed (with its ?token=)"

    def _person_check(self, scope: Scope, headers: dict[str, str], first_load: bool) -> tuple[int, str] | None:
        """A team's person's own secret opens their page (``?person=`` theirs) and the read-only routes;
        no other person's page, and not the shared view's websocket."""
        asked = _query_value(scope, "person")
        if first_load:
            who = self.credentials.person(_query_token(scope))
        else:
            bearer = _bearer(headers)
            who = self.credentials.person(bearer) if bearer else None
            if who is None:  # the cookie of the person asked for, else any person's (read-only routes)
                names = [asked] if asked is not None else [p for p, _ in self.credentials.people]
                who = next((p for p in names if self.credentials.person(_cookie(headers, self.person_cookie(p)))
                            == p), None)
        if who is None:
            return 401, "refused: open the address `hrc console` printed (with its ?token=)"
        if asked is not None and asked != who:
            return 403, f"refused: this secret is {who}'s page's; it opens no other person's page"
        if scope["type"] == "websocket" and asked is None:
            return 403, f"refused: {who}'s secret opens their own page (?person={who}), not the shared view"
        return None

    def person_cookie(self, person: str) -> str:
        """The cookie of a team's person's own page (one per person: two pages in one browser)."""
        return f"{self.cookie}_{person}"

    async def _redirect_with_cookie(self, send: Send, person: str | None = None, token: str = "") -> None:
        """To ``/`` with the cookie set; a team person's page (``&person=ID``, issue 37) keeps its
        ``?person=ID`` (an id of letters, digits, ``_``, ``-`` and ``.`` only; anything else is dropped), and
        their own secret (`token`) sets their own cookie."""
        own = self.credentials.person(token)
        name = self.cookie if own is None else self.person_cookie(own)
        secret = self.credentials.page if own is None else token
        cookie = f"{name}={secret}; HttpOnly; SameSite=Strict; Path=/"
        where = f"/?person={person}" if person is not None and PERSON_PATTERN.fullmatch(person) else "/"
        await send({"type": "http.response.start", "status": 303,
                    "headers": [(b"location", where.encode("ascii")), (b"set-cookie", cookie.encode("ascii")),
                                (b"content-length", b"0"), *_SECURITY]})
        await send({"type": "http.response.body", "body": b""})


_SECURITY = [(b"cache-control", b"no-store"), (b"referrer-policy", b"no-referrer"),
             (b"x-content-type-options", b"nosniff")]


def _headers(scope: Scope) -> dict[str, str]:
    """The request's headers, lower-case names; a repeated Host or Origin makes the value unusable."""
    out: dict[str, str] = {}
    for raw_name, raw_value in scope.get("headers", ()):
        name = raw_name.decode("latin-1").lower()
        value = raw_value.decode("latin-1")
        if name in out and name in ("host", "origin", "authorization"):
            value = "\x00repeated"
        elif name == "cookie" and name in out:
            value = out[name] + "; " + value
        out[name] = value
    return out


def _bearer(headers: dict[str, str]) -> str | None:
    kind, _, token = headers.get("authorization", "").partition(" ")
    return token.strip() if kind.lower() == "bearer" and token.strip() else None


def _cookie(headers: dict[str, str], name: str) -> str | None:
    jar: SimpleCookie = SimpleCookie()
    try:
        jar.load(headers.get("cookie", ""))
    except Exception:  # noqa: BLE001 - a malformed cookie header is no credential
        return None
    morsel = jar.get(name)
    return morsel.value if morsel is not None else None


MAX_QUERY = 1024
"""Bytes of a query string at most (this console reads ``?token=``, ``person=`` and, on /robot, ``robot=``)."""
MAX_QUERY_FIELDS = 8
MAX_HEADERS = 64
"""Header lines of a request at most (uvicorn's h11 bounds their total size: `hrc.console.limits`)."""


def _bounded(scope: Scope) -> tuple[int, str] | None:
    """The refusal of a request whose query string or headers exceed the bounds, or None (issue 34:
    nine query fields made ``parse_qs`` raise, and the server answered 500 with a traceback)."""
    query = scope.get("query_string", b"")
    if len(query) > MAX_QUERY:
        return 414, f"refused: a query string longer than {MAX_QUERY} bytes"
    if query.count(b"&") + query.count(b";") >= MAX_QUERY_FIELDS:
        return 400, f"refused: a query string of more than {MAX_QUERY_FIELDS} fields"
    if len(scope.get("headers", ())) > MAX_HEADERS:
        return 431, f"refused: more than {MAX_HEADERS} header lines"
    return None


def _query_token(scope: Scope) -> str | None:
    return _query_value(scope, "token")


def _query_value(scope: Scope, name: str) -> str | None:
    query = scope.get("query_string", b"").decode("latin-1")
    try:
        values = parse_qs(query, max_num_fields=MAX_QUERY_FIELDS).get(name) if query else None
    except ValueError:  # more fields than allowed (`_bounded` refuses such a request first)
        return None
    return values[-1] if values else None


async def _refuse(scope: Scope, receive: Receive, send: Send, status: int, text: str) -> None:
    body = (text + "\n").encode("utf-8")
    headers = [(b"content-type", b"text/plain; charset=utf-8"), (b"content-length", str(len(body)).encode()),
               *_SECURITY]
    if status == 401:
        headers.append((b"www-authenticate", b'Bearer realm="hrc console"'))
    if scope["type"] == "http":
        await send({"type": "http.response.start", "status": status, "headers": headers})
        await send({"type": "http.response.body", "body": body})
        return
    await receive()  # websocket.connect
    if "websocket.http.response" in scope.get("extensions", {}):
        await send({"type": "websocket.http.response.start", "status": status, "headers": headers})
        await send({"type": "websocket.http.response.body", "body": body})
    else:
        await send({"type": "websocket.close", "code": 1008})
