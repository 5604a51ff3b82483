"""A page opened in a real headless Chromium, driven over the DevTools protocol on a pipe.

``chromium --remote-debugging-pipe`` reads DevTools commands from fd 3 and writes replies and
events to fd 4, each a JSON text ended by a NUL byte: no WebSocket client and no network port is
needed. :class:`HeadlessBrowser` opens a page at a given viewport size, waits for its ``load``
event, evaluates an expression in it and collects what the page printed as an error: console
errors and assertions, uncaught exceptions and the browser's log entries at level ``error``
(a resource that failed to load, a blocked request).
"""

from __future__ import annotations

import json
import os
import select
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

BROWSER_NAMES = ('chromium', 'chromium-browser', 'google-chrome', 'google-chrome-stable')
"""Executables looked up on PATH, in this order (Debian's package installs ``chromium``)."""


def find_browser() -> str | None:
    """Path of a Chromium-based browser on PATH, else None."""
    for name in BROWSER_NAMES:
        if path := shutil.which(name):
            return path
    return None


@dataclass
class PageResult:
    """What a page showed: the expression's value and the errors printed while it loaded."""

    value: Any
    errors: list[str] = field(default_factory=list)


class BrowserError(RuntimeError):
    """The browser did not start, did not answer in time, or a command failed."""


class HeadlessBrowser:
    """One headless Chromium process; use as a context manager.

    Args:
        binary: the browser executable.
        timeout_s: how long any one step (start, command, page load) may take, s.
    """

    def __init__(self, binary: str, timeout_s: float = 60.0) -> None:
        self.timeout_s = timeout_s
        self._profile = tempfile.TemporaryDirectory(prefix='rfi-chromium-')
        to_browser_r, self._to_browser = os.pipe()
        self._from_browser, from_browser_w = os.pipe()

        def pipes_on_3_and_4() -> None:  # in the child, before exec: the fds the browser expects
            high_r = os.dup(to_browser_r) if to_browser_r in (3, 4) else to_browser_r
            high_w = os.dup(from_browser_w) if from_browser_w in (3, 4) else from_browser_w
            os.dup2(high_r, 3)
            os.dup2(high_w, 4)

        args = [binary, '--headless', '--remote-debugging-pipe', '--disable-gpu', '--no-first-run',
                '--no-default-browser-check', '--disable-extensions', '--disable-background-networking',
                '--disable-dev-shm-usage', '--mute-audio', f'--user-data-dir={self._profile.name}']
        if os.geteuid() == 0:  # Chromium refuses to run as root with its sandbox
            args.append('--no-sandbox')
        self._stderr = tempfile.TemporaryFile()  # a file, not a pipe: a chatty browser never blocks on it
        self._process = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                         stderr=self._stderr, close_fds=False, preexec_fn=pipes_on_3_and_4)
        os.close(to_browser_r)
        os.close(from_browser_w)
        self._buffer = b''
        self._next_id = 0
        self._events: list[dict[str, Any]] = []

    def __enter__(self) -> HeadlessBrowser:
        self.command('Browser.getVersion')
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Ask the browser to quit; kill it if it has not within 10 s."""
        if self._process.poll() is None:
            try:
                self._send('Browser.close', {}, None)
                self._process.wait(timeout=10)
            except (OSError, subprocess.TimeoutExpired):
                self._process.kill()
                self._process.wait(timeout=10)
        self._stderr.close()
        for fd in (self._to_browser, self._from_browser):
            try:
                os.close(fd)
            except OSError:
                pass
        self._profile.cleanup()

    # -- protocol ---------------------------------------------------------------------------------
    def _send(self, method: str, params: dict[str, Any], session: str | None) -> int:
        self._next_id += 1
        message: dict[str, Any] = {'id': self._next_id, 'method': method, 'params': params}
        if session:
            message['sessionId'] = session
        os.write(self._to_browser, json.dumps(message).encode() + b'\0')
        return self._next_id

    def _receive(self, deadline: float) -> dict[str, Any]:
        while b'\0' not in self._buffer:
            left = deadline - time.monotonic()
            if left <= 0:
                raise BrowserError(f'no answer from the browser within {self.timeout_s:g} s')
            ready, _, _ = select.select([self._from_browser], [], [], left)
            if ready:
                chunk = os.read(self._from_browser, 1 << 16)
                if not chunk:
                    self._stderr.seek(0)
                    stderr = self._stderr.read().decode(errors='replace')
                    raise BrowserError(f'the browser closed its DevTools pipe (exit {self._process.poll()}): '
                                       f'{stderr[-2000:]}')
                self._buffer += chunk
        text, self._buffer = self._buffer.split(b'\0', 1)
        return json.loads(text)

    def command(self, method: str, params: dict[str, Any] | None = None, session: str | None = None) -> Any:
        """Send a DevTools command and return its result; events that arrive meanwhile are kept."""
        sent = self._send(method, params or {}, session)
        deadline = time.monotonic() + self.timeout_s
        while True:
            message = self._receive(deadline)
            if message.get('id') == sent:
                if 'error' in message:
                    raise BrowserError(f'{method}: {message["error"]}')
                return message.get('result', {})
            if 'method' in message:
                self._events.append(message)

    def _wait_event(self, method: str, session: str) -> None:
        deadline = time.monotonic() + self.timeout_s
        for i, event in enumerate(self._events):
            if event['method'] == method and event.get('sessionId') == session:
                del self._events[i]
                return
        while True:
            message = self._receive(deadline)
            if message.get('method') == method and message.get('sessionId') == session:
                return
            if 'method' in message:
                self._events.append(message)

    # -- pages ------------------------------------------------------------------------------------
    def open(self, path: Path, expression: str, *, width: int, height: int, mobile: bool = False) -> PageResult:
        """Load ``path`` in a new tab of ``width`` x ``height`` CSS pixels and evaluate ``expression``.

        Returns:
            The expression's value (JSON-able) and the errors printed from the start of the load
            up to the evaluation.
        """
        target = self.command('Target.createTarget', {'url': 'about:blank'})['targetId']
        session = self.command('Target.attachToTarget', {'targetId': target, 'flatten': True})['sessionId']
        try:
            for domain in ('Page', 'Runtime', 'Log'):
                self.command(f'{domain}.enable', session=session)
            self.command('Emulation.setDeviceMetricsOverride',
                         {'width': width, 'height': height, 'deviceScaleFactor': 2 if mobile else 1,
                          'mobile': mobile}, session)
            self._events = [e for e in self._events if e.get('sessionId') != session]
            navigation = self.command('Page.navigate', {'url': path.resolve().as_uri()}, session)
            if navigation.get('errorText'):
                raise BrowserError(f'cannot open {path}: {navigation["errorText"]}')
            self._wait_event('Page.loadEventFired', session)
            result = self.command('Runtime.evaluate', {'expression': expression, 'returnByValue': True}, session)
            if 'exceptionDetails' in result:
                raise BrowserError(f'the check failed in the page: {result["exceptionDetails"]}')
            errors = [_error_text(e) for e in self._events if e.get('sessionId') == session]
            return PageResult(result['result'].get('value'), [e for e in errors if e])
        finally:
            self._events = [e for e in self._events if e.get('sessionId') != session]
            self.command('Target.closeTarget', {'targetId': target})


def _error_text(event: dict[str, Any]) -> str:
    """The text of an event that reports an error, '' for any other event."""
    params = event.get('params', {})
    if event['method'] == 'Runtime.consoleAPICalled' and params.get('type') in ('error', 'assert'):
        return 'console.' + params['type'] + ': ' + ' '.join(
            str(a.get('value', a.get('description', ''))) for a in params.get('args', []))
    if event['method'] == 'Runtime.exceptionThrown':
        details = params.get('exceptionDetails', {})
        return 'exception: ' + str(details.get('exception', {}).get('description', details.get('text', '')))
    if event['method'] == 'Log.entryAdded' and params.get('entry', {}).get('level') == 'error':
        entry = params['entry']
        return f'log ({entry.get("source")}): {entry.get("text")} {entry.get("url", "")}'.strip()
    return ''
