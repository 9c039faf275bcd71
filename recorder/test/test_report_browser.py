"""The HTML run report in a real browser: headless Chromium (Debian's package, which
``make setup`` installs) opens report.html over the DevTools protocol; the page must render its
summary and every plot (each image decoded, with its size) with no console error."""

import asyncio
import json
import shutil
import subprocess
import time
from pathlib import Path
from urllib.request import Request, urlopen

import pytest
from test_report import stopping_run
from tornado.websocket import websocket_connect

from recorder.report import main

CHROMIUM = shutil.which('chromium') or shutil.which('chromium-browser')

PAGE_CHECK = """JSON.stringify({
  title: document.title,
  summaryRows: document.querySelectorAll('#summary tr').length,
  tables: Array.from(document.querySelectorAll('table')).map(t => t.id),
  stations: Array.from(document.querySelectorAll('#stations tr td:first-child')).map(
    c => c.textContent),
  images: Array.from(document.images).map(i => ({
    alt: i.alt, complete: i.complete, width: i.naturalWidth, height: i.naturalHeight,
    shown: i.getBoundingClientRect().width})),
})"""


def start_browser(profile: Path) -> tuple[subprocess.Popen, int]:
    """Headless Chromium with DevTools on a free port (the port it writes to its profile)."""
    browser = subprocess.Popen(
        [CHROMIUM, '--headless=new', '--no-sandbox', '--disable-gpu', '--no-first-run',
         '--remote-debugging-port=0', f'--user-data-dir={profile}', 'about:blank'],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    port_file = profile / 'DevToolsActivePort'
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if port_file.exists() and port_file.read_text().strip():
            return browser, int(port_file.read_text().split()[0])
        if browser.poll() is not None:
            break
        time.sleep(0.1)
    browser.kill()
    pytest.fail('Chromium did not start its DevTools server')


async def open_page(port: int, url: str) -> tuple[dict, list[str]]:
    """Load ``url`` in a new tab; (what PAGE_CHECK finds, the console errors and exceptions)."""
    with urlopen(Request(f'http://127.0.0.1:{port}/json/new?about:blank', method='PUT'),
                 timeout=30) as answer:
        target = json.load(answer)
    connection = await websocket_connect(target['webSocketDebuggerUrl'],
                                         max_message_size=64 * 1024 * 1024)
    errors: list[str] = []
    ids = iter(range(1, 1_000_000))

    async def call(method: str, **params) -> dict:
        request_id = next(ids)
        connection.write_message(json.dumps({'id': request_id, 'method': method,
                                             'params': params}))
        while True:
            message = await asyncio.wait_for(connection.read_message(), 60)
            assert message is not None, 'the DevTools connection closed'
            body = json.loads(message)
            note(body)
            if body.get('id') == request_id:
                assert 'error' not in body, body
                return body['result']

    def note(body: dict) -> None:
        method, params = body.get('method'), body.get('params', {})
        if method == 'Runtime.consoleAPICalled' and params['type'] in ('error', 'assert'):
            errors.append(f"console.{params['type']}: {params['args']}")
        elif method == 'Runtime.exceptionThrown':
            errors.append(f"exception: {params['exceptionDetails']}")
        elif method == 'Log.entryAdded' and params['entry']['level'] == 'error':
            errors.append(f"log: {params['entry']['text']} ({params['entry'].get('url')})")

    for domain in ('Page', 'Runtime', 'Log'):
        await call(f'{domain}.enable')
    await call('Page.navigate', url=url)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:  # until the load event (every image decoded)
        body = json.loads(await asyncio.wait_for(connection.read_message(), 60))
        note(body)
        if body.get('method') == 'Page.loadEventFired':
            break
    found = await call('Runtime.evaluate', expression=PAGE_CHECK, returnByValue=True)
    shot = await call('Page.captureScreenshot', format='png')
    connection.close()
    return dict(json.loads(found['result']['value']), screenshot=len(shot['data'])), errors


def test_the_html_report_renders_every_plot_in_chromium(tmp_path):
    assert CHROMIUM, 'Chromium is not installed: `make setup` installs it (apt-get install ' \
                     'chromium) for this test'
    bag, scenario = stopping_run(tmp_path, lag_m=0.25)
    assert main([str(bag), '--scenario', str(scenario), '--output',
                 str(tmp_path / 'report')]) == 0
    pngs = sorted(p.stem for p in (tmp_path / 'report').glob('*.png'))
    browser, port = start_browser(tmp_path / 'profile')
    try:
        page, errors = asyncio.run(open_page(port, (tmp_path / 'report' /
                                                    'report.html').as_uri()))
    finally:
        browser.terminate()
        try:
            browser.wait(timeout=20)
        except subprocess.TimeoutExpired:
            browser.kill()
    assert errors == []
    assert page['title'] == 'Run report: stopping_line (run)'
    assert page['summaryRows'] >= 5
    assert page['tables'] == ['journey', 'summary', 'stations']  # no windows, no events: text
    assert page['stations'] == ['Halt', 'End']
    assert sorted(i['alt'] for i in page['images']) == pngs and 'tracking' in pngs
    for image in page['images']:
        assert image['complete'] and image['width'] > 100 and image['height'] > 100, image
        assert image['shown'] > 100, image  # laid out, not collapsed
    assert page['screenshot'] > 1000
