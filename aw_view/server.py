"""The HTTP server: two pages and a small JSON API that the pages poll (standard library
``http.server``, one thread per connection; nothing to install, and a slow or closed browser
only ever holds its own thread).

Routes (``ID`` is an episode's path below the watched folder):

- ``/``: the runs page; ``/episode/ID``: an episode's page; ``/assets/NAME``: their scripts
  and styles, the report's 3D viewer (``viewer.js``) and plotly's offline bundle;
- ``/api/runs``: every episode's row (``ETag``: a repeated request costs a 304);
- ``/api/episode?id=ID&from=K``: the episode's calls from the K-th on, with their states;
- ``/api/scene?id=ID``: the task's parts as the 3D view draws them;
- ``/api/score?id=ID&want=K``: with ``--suite``, every state's scores and state K's ghost
  (without it, ``{"enabled": false}``);
- ``/capture?id=ID&name=captures/NNNNNN.png[&thumb=1]``, ``/reference?id=ID&k=K``: images.

With a token (``--host`` other than loopback), every request needs it, as ``?token=`` (the
printed URL) or as the cookie that URL sets; without one, only requests naming this machine as
their ``Host`` are served (a page elsewhere cannot reach the viewer through DNS rebinding).
"""

from __future__ import annotations

import hmac
import io
import mimetypes
import sys
import threading
from functools import cache, lru_cache
from http import HTTPStatus
from http.cookies import SimpleCookie
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from importlib.util import find_spec
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, quote, unquote, urlsplit

import orjson

from aw_view.watch import Watch

__all__ = ["ViewerServer", "serve_in_thread", "episode_path", "LOOPBACK_HOSTS"]

LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1")
THUMB_SIZE = (160, 120)
_COOKIE = "aw_view_token"
_PAGES = {"runs": "runs.html", "episode": "episode.html"}
_OWN_ASSETS = ("runs.js", "episode.js", "view.css")
_SECURITY = {
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "X-Frame-Options": "DENY",
    # plotly compiles its WebGL shaders with Function(), and sets inline styles
    "Content-Security-Policy": "default-src 'self'; script-src 'self' 'unsafe-eval'; style-src 'self' "
    "'unsafe-inline'; img-src 'self' data: blob:; connect-src 'self'; frame-ancestors 'none'",
}


def episode_path(rid: str) -> str:
    """The URL path of an episode's page."""
    return "/episode/" + quote(rid, safe="/")


@cache
def _own_asset(name: str) -> bytes:
    return (resources.files("aw_view") / "assets" / name).read_bytes()


@lru_cache(maxsize=1)
def _report_viewer() -> bytes:
    """The report's 3D viewer script (``aw_eval/report/html/assets/viewer.js``), read from the
    package folder without importing ``aw_eval`` (which would load the evaluator)."""
    spec = find_spec("aw_eval")
    if spec is None or not spec.submodule_search_locations:
        raise FileNotFoundError("aw_eval is not installed: the 3D view's script is missing")
    return (Path(list(spec.submodule_search_locations)[0]) / "report" / "html" / "assets" / "viewer.js").read_bytes()


@lru_cache(maxsize=1)
def _plotly() -> bytes:
    from plotly.offline import get_plotlyjs

    return get_plotlyjs().encode("utf-8")


@lru_cache(maxsize=512)
def _thumbnail(path: str, stamp: int) -> bytes:
    from PIL import Image

    with Image.open(path) as src:
        im = src.convert("RGB")
    im.thumbnail(THUMB_SIZE)
    buf = io.BytesIO()
    im.save(buf, format="JPEG", quality=80)
    return buf.getvalue()


class ViewerServer(ThreadingHTTPServer):
    daemon_threads = True
    allow_reuse_address = True

    def __init__(self, address: tuple[str, int], watch: Watch, token: str | None):
        self.watch = watch
        self.token = token
        super().__init__(address, _Handler)

    @property
    def port(self) -> int:
        return int(self.server_address[1])


class _Handler(BaseHTTPRequestHandler):
    server: ViewerServer
    server_version = "aw-view"
    sys_version = ""

    def log_message(self, format: str, *args: Any) -> None:  # the base class names it `format`
        pass  # one line per request would bury the URL; errors are answered, not logged

    # ------------------------------------------------------------------ plumbing
    def _send(
        self,
        status: int,
        body: bytes,
        ctype: str,
        etag: str | None = None,
        cache: str = "no-cache",
        cookie: str | None = None,
    ) -> None:
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", cache)
        if etag:
            self.send_header("ETag", etag)
        if cookie:
            self.send_header("Set-Cookie", f"{_COOKIE}={cookie}; Path=/; HttpOnly; SameSite=Strict")
        for k, v in _SECURITY.items():
            self.send_header(k, v)
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def _json(self, obj: Any, status: int = 200, etag: str | None = None) -> None:
        if etag and self.headers.get("If-None-Match") == etag:
            self._send(HTTPStatus.NOT_MODIFIED, b"", "application/json", etag)
            return
        body = obj if isinstance(obj, bytes) else orjson.dumps(obj, option=orjson.OPT_SERIALIZE_NUMPY)
        self._send(status, body, "application/json", etag)

    def _error(self, status: int, message: str) -> None:
        self._json({"error": message}, status)

    def _authorized(self, query: dict[str, list[str]]) -> tuple[bool, str | None]:
        """``(allowed, cookie to set)``."""
        token = self.server.token
        if token is None:
            host = (self.headers.get("Host") or "").rsplit(":", 1)[0].strip("[]")
            return host in LOOPBACK_HOSTS, None
        given = (query.get("token") or [""])[0]
        if given and hmac.compare_digest(given.encode(), token.encode()):
            return True, token
        jar = SimpleCookie()
        try:
            jar.load(self.headers.get("Cookie") or "")
        except Exception:  # a malformed cookie header is no token
            return False, None
        morsel = jar.get(_COOKIE)
        return bool(morsel and hmac.compare_digest(morsel.value.encode(), token.encode())), None

    def do_HEAD(self) -> None:
        self.do_GET()

    def do_GET(self) -> None:
        try:
            self._route()
        except (BrokenPipeError, ConnectionResetError):
            pass  # the browser went away: nothing to answer
        except Exception as exc:  # never a traceback to the page or the terminal
            try:
                self._error(500, f"internal error: {type(exc).__name__}: {exc}")
            except OSError:
                pass
            print(f"aw-view: error answering {self.path[:200]}: {type(exc).__name__}: {exc}", file=sys.stderr)

    # ------------------------------------------------------------------ routes
    def _route(self) -> None:
        url = urlsplit(self.path)
        query = parse_qs(url.query)
        ok, cookie = self._authorized(query)
        if not ok:
            why = (
                "open the URL that aw-view printed (it carries the token)"
                if self.server.token
                else ("this viewer answers requests addressed to this machine (127.0.0.1 or localhost) only")
            )
            self._error(403, f"forbidden: {why}")
            return
        path = unquote(url.path)
        watch = self.server.watch
        if path == "/":
            self._send(200, _own_asset(_PAGES["runs"]), "text/html; charset=utf-8", cookie=cookie)
        elif path.startswith("/episode/"):
            self._send(200, _own_asset(_PAGES["episode"]), "text/html; charset=utf-8", cookie=cookie)
        elif path.startswith("/assets/"):
            self._asset(path[len("/assets/") :])
        elif path == "/favicon.ico":
            self._send(HTTPStatus.NO_CONTENT, b"", "image/x-icon", cache="max-age=86400")
        elif path == "/api/runs":
            body, etag = watch.runs()
            self._json(body, etag=etag)
        elif path == "/api/episode":
            self._episode(query)
        elif path == "/api/scene":
            scene = watch.scene(_arg(query, "id"))
            self._json(scene) if scene is not None else self._error(404, "no such episode")
        elif path == "/api/score":
            self._score(query)
        elif path == "/capture":
            self._capture(query)
        elif path == "/reference":
            self._reference(query)
        else:
            self._error(404, f"no page {path[:200]!r}")

    def _asset(self, name: str) -> None:
        long = "max-age=86400"
        if name in _OWN_ASSETS:
            ctype = "text/css" if name.endswith(".css") else "text/javascript"
            self._send(200, _own_asset(name), f"{ctype}; charset=utf-8")
        elif name == "viewer.js":
            self._send(200, _report_viewer(), "text/javascript; charset=utf-8")
        elif name == "plotly.min.js":
            self._send(200, _plotly(), "text/javascript; charset=utf-8", cache=long)
        else:
            self._error(404, f"no asset {name[:100]!r}")

    def _episode(self, query: dict[str, list[str]]) -> None:
        try:
            start = int(_arg(query, "from") or 0)
        except ValueError:
            self._error(400, "from must be an integer")
            return
        found = self.server.watch.detail(_arg(query, "id"), start)
        if found is None:
            self._error(404, "no such episode under the watched folder")
            return
        body, etag = found
        self._json(body, etag=etag)

    def _score(self, query: dict[str, list[str]]) -> None:
        watch = self.server.watch
        if watch.scorer is None:
            self._json({"enabled": False, "note": "start aw-view with --suite SUITE to see the target and scores"})
            return
        try:
            want = int(_arg(query, "want") or -1)
        except ValueError:
            self._error(400, "want must be an integer")
            return
        report = watch.score(_arg(query, "id"), want)
        self._json(report) if report is not None else self._error(404, "no such episode")

    def _image(self, path: Path | None, thumb: bool) -> None:
        if path is None:
            self._error(404, "no such image")
            return
        try:
            if thumb:
                body = _thumbnail(str(path), path.stat().st_mtime_ns)
                ctype = "image/jpeg"
            else:
                body = self.server.watch.public.read_bytes(path)
                ctype = mimetypes.guess_type(path.name)[0] or "application/octet-stream"
        except FileNotFoundError:
            self._error(404, "no such image (deleted?)")
            return
        except Exception as exc:  # a damaged image is a 404 with its reason
            self._error(404, f"the image cannot be read: {type(exc).__name__}")
            return
        self._send(200, body, ctype, cache="max-age=5")

    def _capture(self, query: dict[str, list[str]]) -> None:
        self._image(self.server.watch.capture(_arg(query, "id"), _arg(query, "name")), _arg(query, "thumb") == "1")

    def _reference(self, query: dict[str, list[str]]) -> None:
        try:
            k = int(_arg(query, "k"))
        except ValueError:
            self._error(400, "k must be an integer")
            return
        self._image(self.server.watch.reference(_arg(query, "id"), k), _arg(query, "thumb") == "1")


def _arg(query: dict[str, list[str]], name: str) -> str:
    return (query.get(name) or [""])[0]


def serve_in_thread(server: ViewerServer) -> threading.Thread:
    """Serve until ``server.shutdown()`` (tests and benchmarks run the viewer in-process this way)."""
    thread = threading.Thread(target=server.serve_forever, name="aw-view", daemon=True)
    thread.start()
    return thread
