"""Headless Chromium for checking and capturing reports: find it, run it, read what it did.

* :func:`dump_dom` — the DOM after the page's scripts ran (``--dump-dom`` with a virtual time
  budget), optionally with a NetLog of every request (``--log-net-log``).
* :func:`capture_png` — a screenshot of the page.
* :func:`plot_render_status` — for each plotly figure div in a DOM, whether plotly drew its SVG.
* :func:`static_external_references` — every ``src``/``href``/CSS ``url()`` of a page that
  would load something from the network.
* :func:`netlog_requests` / :func:`page_network_requests` — requests in a NetLog, and those the
  page itself made.

Chromium runs with the flags of :data:`CHROMIUM_FLAGS` and a fresh ``--user-data-dir``. Even with
``--disable-background-networking`` the browser process itself still pings a few Google services
(update checks, sign-in); NetLog marks those with initiator ``"not an origin"`` and a network
isolation key that is not the page's. Requests the *page* makes carry the page's origin as
initiator (``"null"`` for ``file://``) or its site in the isolation key; those are the ones
:func:`page_network_requests` returns.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from html.parser import HTMLParser
from pathlib import Path

__all__ = [
    "CHROMIUM_FLAGS", "ChromiumError", "find_chromium", "dump_dom", "capture_png",
    "plot_render_status", "static_external_references", "NetRequest", "netlog_requests",
    "page_network_requests", "LOCAL_SCHEMES",
]

CHROMIUM_FLAGS: tuple[str, ...] = (
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
)
LOCAL_SCHEMES = ("file:", "data:", "blob:", "about:")
_ENV_VAR = "SOLNIC_BENCH_CHROMIUM"


class ChromiumError(RuntimeError):
    """Chromium is missing, failed, or timed out."""


def find_chromium() -> str | None:
    """Path of a Chromium binary: ``$SOLNIC_BENCH_CHROMIUM``, else ``chromium`` or
    ``chromium-browser`` on PATH; None if there is none."""
    env = os.environ.get(_ENV_VAR)
    if env:
        return env if Path(env).exists() else shutil.which(env)
    for name in ("chromium", "chromium-browser"):
        path = shutil.which(name)
        if path:
            return path
    return None


def _run(page: Path, args: Sequence[str], *, chromium: str | None, timeout: float,
         netlog: Path | None) -> subprocess.CompletedProcess[str]:
    exe = chromium or find_chromium()
    if exe is None:
        raise ChromiumError("Chromium not found: install Debian's 'chromium' or set "
                            f"${_ENV_VAR}")
    page = Path(page).resolve()
    if not page.is_file():
        raise FileNotFoundError(f"page {str(page)!r} does not exist")
    with tempfile.TemporaryDirectory(prefix="solnic-chromium-") as profile:
        cmd = [exe, *CHROMIUM_FLAGS, f"--user-data-dir={profile}"]
        if netlog is not None:
            cmd += [f"--log-net-log={Path(netlog).resolve()}", "--net-log-capture-mode=Default"]
        cmd += [*args, page.as_uri()]
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout,
                                  stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired as exc:
            raise ChromiumError(f"Chromium timed out after {timeout} s: {' '.join(cmd)}") from exc
    if proc.returncode != 0:
        raise ChromiumError(f"Chromium exited with {proc.returncode}: {proc.stderr[-2000:]}")
    return proc


def dump_dom(page: Path | str, *, netlog: Path | str | None = None, budget_ms: int = 20000,
             chromium: str | None = None, timeout: float = 180.0) -> str:
    """The serialised DOM of ``page`` after its scripts ran for ``budget_ms`` of virtual time."""
    proc = _run(Path(page), ["--dump-dom", f"--virtual-time-budget={int(budget_ms)}"],
                chromium=chromium, timeout=timeout,
                netlog=None if netlog is None else Path(netlog))
    return proc.stdout


def capture_png(page: Path | str, png: Path | str, *, width: int = 1400, height: int = 4000,
                budget_ms: int = 20000, chromium: str | None = None,
                timeout: float = 180.0) -> Path:
    """Screenshot of the top ``width × height`` pixels of ``page`` after its scripts ran."""
    png = Path(png).resolve()
    png.parent.mkdir(parents=True, exist_ok=True)
    _run(Path(page), [f"--screenshot={png}", f"--window-size={int(width)},{int(height)}",
                      "--hide-scrollbars", f"--virtual-time-budget={int(budget_ms)}"],
         chromium=chromium, timeout=timeout, netlog=None)
    if not png.is_file() or png.stat().st_size == 0:
        raise ChromiumError(f"Chromium wrote no screenshot to {png}")
    return png


class _PlotParser(HTMLParser):
    """Tracks, for each ``div.plotly-graph-div``, whether an ``svg.main-svg`` lies inside it."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.status: dict[str, bool] = {}
        self._current: str | None = None
        self._depth = 0

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        classes = (a.get("class") or "").split()
        if tag == "div":
            if self._current is not None:
                self._depth += 1
            elif "plotly-graph-div" in classes:
                self._current = a.get("id") or f"<anonymous {len(self.status)}>"
                self.status[self._current] = False
                self._depth = 1
        elif tag == "svg" and self._current is not None and "main-svg" in classes:
            self.status[self._current] = True

    def handle_endtag(self, tag: str) -> None:
        if tag == "div" and self._current is not None:
            self._depth -= 1
            if self._depth == 0:
                self._current = None


def plot_render_status(dom: str) -> dict[str, bool]:
    """``{div id: drawn}`` for every plotly figure div in ``dom``; drawn = holds ``svg.main-svg``."""
    p = _PlotParser()
    p.feed(dom)
    p.close()
    return p.status


_URL_ATTRS = {"src", "href", "srcset", "poster", "data", "action", "formaction", "background",
              "xlink:href", "manifest", "ping"}


class _RefParser(HTMLParser):
    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.refs: list[str] = []
        self._in_style = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self._in_style = tag == "style"
        for name, value in attrs:
            if value is None:
                continue
            if name in _URL_ATTRS:
                urls = ([p.strip().split()[0] for p in value.split(",") if p.strip()]
                        if name == "srcset" else [value.strip()])
                self.refs += [f"<{tag} {name}={u!r}>" for u in urls if _is_remote(u)
                              and not (tag == "a" and name == "href" and _is_sibling(u))]
            elif name == "style":
                self.refs += [f"<{tag} style> {u}" for u in _css_urls(value) if _is_remote(u)]
            elif name == "http-equiv" and value.lower() == "refresh":
                self.refs.append(f"<{tag} http-equiv=refresh>")

    def handle_endtag(self, tag: str) -> None:
        if tag == "style":
            self._in_style = False

    def handle_data(self, data: str) -> None:
        if self._in_style:
            self.refs += [f"<style> {u}" for u in _css_urls(data) if _is_remote(u)]
            if "@import" in data:
                self.refs.append("<style> @import")


def _css_urls(css: str) -> list[str]:
    out, i = [], 0
    while (j := css.find("url(", i)) >= 0:
        k = css.find(")", j)
        if k < 0:
            break
        out.append(css[j + 4:k].strip().strip("'\""))
        i = k + 1
    return out


def _is_sibling(url: str) -> bool:
    """A relative path inside the run directory (``results.csv``, ``traces/x.rrd``): an ``<a>``
    to it is a link the reader may follow, not a load, and it never leaves the machine."""
    u = url.strip()
    return bool(u) and ":" not in u.split("/")[0] and not u.startswith(("/", "\\")) and ".." not in u.split("/")


def _is_remote(url: str) -> bool:
    """True for anything the browser would fetch from the network (http(s), ws, ftp, //host)."""
    u = url.strip().lower()
    if not u or u.startswith("#") or u.startswith("javascript:"):
        return False
    return not u.startswith(LOCAL_SCHEMES)


def static_external_references(html: str) -> list[str]:
    """Every attribute or CSS reference in ``html`` that would load from the network.

    Script and style *text* is not scanned as HTML (plotly.js mentions URLs in strings it never
    fetches here); CSS ``url()`` and ``@import`` in ``<style>`` blocks are.
    Relative references (e.g. ``foo.png``) count too: a self-contained page has none.
    """
    p = _RefParser()
    p.feed(html)
    p.close()
    return p.refs


@dataclass(frozen=True)
class NetRequest:
    """One URL request seen in a NetLog."""

    url: str
    initiator: str
    isolation_key: str

    @property
    def from_page(self) -> bool:
        """Made on behalf of a page (not a browser-process background request)."""
        return self.initiator != "not an origin" or "file://" in self.isolation_key


def netlog_requests(netlog: Path | str) -> list[NetRequest]:
    """Every URL request Chromium logged (``URL_REQUEST_START_JOB`` events)."""
    text = Path(netlog).read_text(encoding="utf-8", errors="replace")
    try:
        log = json.loads(text)
    except json.JSONDecodeError:  # Chromium killed before closing the log
        log = json.loads(text.rstrip().rstrip(",") + "]}")
    types = log["constants"]["logEventTypes"]
    start = types.get("URL_REQUEST_START_JOB")
    out = []
    for ev in log.get("events", []):
        if ev.get("type") == start and "url" in ev.get("params", {}):
            p = ev["params"]
            out.append(NetRequest(p["url"], str(p.get("initiator", "")),
                                  str(p.get("network_isolation_key", ""))))
    return out


def page_network_requests(netlog: Path | str) -> list[NetRequest]:
    """Requests made on behalf of the page whose URL is not local (file:, data:, blob:, about:)."""
    return [r for r in netlog_requests(netlog)
            if r.from_page and not r.url.lower().startswith(LOCAL_SCHEMES)]
