"""The per-subject report page (scan2morph.report.html, .provenance) and the Snakemake report.

The page is built from a tiny finished run's store (tests/support/tiny_run.py) with the fit stage's
figures, opened in headless Chromium through the DevTools protocol (no console error, every image
decoded), and its tables are read back and compared with the store, the accuracy file and the
benchmark files they come from.
"""

from __future__ import annotations

import base64
import csv
import html
import json
import os
import re
import shutil
import socket
import struct
import subprocess
import sys
import time
import urllib.request
from html.parser import HTMLParser
from pathlib import Path

import cv2
import h5py
import numpy as np
import pytest

from scan2morph.errors import InputError
from scan2morph.geometry import TexturedMesh
from scan2morph.io import read_glb_targets
from scan2morph.report import (
    ReportFigure,
    ReportPage,
    clear_stale,
    image_uri,
    mark_stale,
    read_caption,
    sections,
    software_versions,
    stage_timings,
    subject_report_html,
    thumbnail_jpeg,
    write_subject_report,
)
from scan2morph.report import accuracy as report_accuracy
from scan2morph.report.viewer import VIEWER_BUNDLE, script_hash, three_unavailable, viewer_script
from scan2morph.store import paths
from scan2morph.template import build_template, subdivide_template
from tests.support.configs import repo_config
from tests.support.tiny_run import SUBJECT, TAKES, tiny_run
from tests.support.workflow_api import REPO

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
needs_chromium = pytest.mark.skipif(
    CHROMIUM is None,
    reason="headless Chromium not installed (Debian package 'chromium', installed by make setup)",
)
#: Why the report has no 3D viewer here (three.js not installed by make setup), or None.
THREE_MISSING = three_unavailable()
needs_three = pytest.mark.skipif(THREE_MISSING is not None, reason=str(THREE_MISSING))
CAPTIONS = REPO / "workflow" / "report" / "figures"
THUMB_PX = 80


# --- a minimal DevTools protocol client (stdlib only: no websocket package is installed) ---
class _WebSocket:
    """Text-frame websocket client (RFC 6455), enough for the DevTools protocol."""

    def __init__(self, url: str, timeout: float = 30.0):
        hostport, _, path = url.removeprefix("ws://").partition("/")
        host, _, port = hostport.partition(":")
        self.sock = socket.create_connection((host, int(port)), timeout=timeout)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            (
                f"GET /{path} HTTP/1.1\r\nHost: {hostport}\r\nUpgrade: websocket\r\n"
                f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                "Sec-WebSocket-Version: 13\r\n\r\n"
            ).encode()
        )
        head = b""
        while not head.endswith(b"\r\n\r\n"):
            head += self._read(1)
        if b" 101 " not in head.split(b"\r\n", 1)[0]:
            raise ConnectionError(head.decode(errors="replace"))

    def _read(self, n: int) -> bytes:
        buf = b""
        while len(buf) < n:
            chunk = self.sock.recv(n - len(buf))
            if not chunk:
                raise ConnectionError("websocket closed")
            buf += chunk
        return buf

    def send(self, text: str) -> None:
        data, mask = text.encode(), os.urandom(4)
        n = len(data)
        if n < 126:
            head = struct.pack("!BB", 0x81, 0x80 | n)
        elif n < 1 << 16:
            head = struct.pack("!BBH", 0x81, 0x80 | 126, n)
        else:
            head = struct.pack("!BBQ", 0x81, 0x80 | 127, n)
        body = (
            np.frombuffer(data, np.uint8) ^ np.resize(np.frombuffer(mask, np.uint8), n)
        ).tobytes()
        self.sock.sendall(head + mask + body)

    def recv(self) -> str:
        parts = []
        while True:
            b0, b1 = self._read(2)
            n = b1 & 0x7F
            if n == 126:
                (n,) = struct.unpack("!H", self._read(2))
            elif n == 127:
                (n,) = struct.unpack("!Q", self._read(8))
            payload = self._read(n)
            opcode = b0 & 0x0F
            if opcode == 0x8:
                raise ConnectionError("websocket closed by the browser")
            if opcode in (0x9, 0xA):  # ping / pong
                continue
            parts.append(payload)
            if b0 & 0x80:
                return b"".join(parts).decode()

    def close(self) -> None:
        self.sock.close()


class Browser:
    """Headless Chromium with a DevTools endpoint; :meth:`inspect` loads a page and reports."""

    def __init__(self, profile: Path):
        self.proc = subprocess.Popen(
            [
                CHROMIUM,
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                # WebGL for the 3D viewer on the CPU (SwiftShader), without the deprecation
                # warning of the automatic fallback
                "--use-angle=swiftshader",
                "--enable-unsafe-swiftshader",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                f"--user-data-dir={profile}",
                "--remote-debugging-port=0",
                "about:blank",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        port_file = profile / "DevToolsActivePort"
        deadline = time.monotonic() + 30
        while not (port_file.is_file() and port_file.read_text().strip()):
            if time.monotonic() > deadline or self.proc.poll() is not None:
                self.close()
                raise RuntimeError("chromium did not open its DevTools port")
            time.sleep(0.05)
        self.port = int(port_file.read_text().split()[0])

    def inspect(self, url: str, actions=None) -> dict:
        """Load ``url`` in a new tab; its errors, images, fetched resources and scripts.

        ``actions(evaluate, call)``, when given, runs after the load event (``evaluate`` returns
        a JavaScript expression's value, awaiting promises; ``call`` sends a DevTools command);
        what it returns is the result's ``actions``.
        """
        req = urllib.request.Request(
            f"http://127.0.0.1:{self.port}/json/new?about:blank", method="PUT"
        )
        with urllib.request.urlopen(req, timeout=30) as resp:
            target = json.load(resp)
        ws = _WebSocket(target["webSocketDebuggerUrl"])
        events: list[dict] = []
        ids = iter(range(1, 1 << 30))

        def call(method, **params):
            i = next(ids)
            ws.send(json.dumps({"id": i, "method": method, "params": params}))
            while True:
                msg = json.loads(ws.recv())
                if msg.get("id") == i:
                    if "error" in msg:
                        raise RuntimeError(f"{method}: {msg['error']}")
                    return msg["result"]
                events.append(msg)

        def evaluate(expression):
            result = call(
                "Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True
            )
            if "exceptionDetails" in result:
                raise RuntimeError(f"{expression[:80]}: {result['exceptionDetails']}")
            return result["result"].get("value")

        try:
            for domain in ("Runtime", "Log", "Page"):
                call(f"{domain}.enable")
            call("Page.navigate", url=url)
            while not any(e.get("method") == "Page.loadEventFired" for e in events):
                events.append(json.loads(ws.recv()))
            images = json.loads(
                evaluate(
                    "JSON.stringify(Array.from(document.images, i => ({alt: i.alt, complete: "
                    "i.complete, width: i.naturalWidth, height: i.naturalHeight, "
                    "data: i.src.startsWith('data:')})))"
                )
            )
            done = actions(evaluate, call) if actions is not None else None
            resources = evaluate("performance.getEntriesByType('resource').map(e => e.name)")
            active = evaluate(
                "document.querySelectorAll('script[src], link, iframe, object, embed').length"
            )
            scripts = evaluate(
                "Array.from(document.scripts, s => ({type: s.type, src: s.src, "
                "chars: s.text.length}))"
            )
        finally:
            ws.close()
        errors = []
        for e in events:
            method, params = e.get("method"), e.get("params", {})
            if method == "Runtime.exceptionThrown":
                errors.append(params["exceptionDetails"].get("text", "exception"))
            elif method == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
                errors.append(" ".join(str(a.get("value")) for a in params.get("args", [])))
            elif method == "Log.entryAdded" and params["entry"]["level"] == "error":
                errors.append(params["entry"]["text"])
        found = dict(errors=errors, images=images, resources=resources, active=active)
        return found | {"scripts": scripts, "actions": done}

    def close(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


# --- reading the page back ---
class _Tables(HTMLParser):
    """Every table's caption and cell texts, and every image's alt and src."""

    def __init__(self):
        super().__init__()
        self.tables: dict[str, list[list[str]]] = {}
        self.images: list[dict] = []
        self.captions: list[str] = []
        self._table = self._row = self._cell = self._cap = self._fig = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "table":
            self._table, self._name = [], ""
        elif tag == "caption":
            self._cap = ""
        elif tag == "tr":
            self._row = []
        elif tag in ("td", "th"):
            self._cell = ""
        elif tag == "img":
            self.images.append(a)
        elif tag == "figcaption":
            self._fig = ""

    def handle_data(self, data):
        for name in ("_cell", "_cap", "_fig"):
            if getattr(self, name) is not None:
                setattr(self, name, getattr(self, name) + data)

    def handle_endtag(self, tag):
        if tag in ("td", "th"):
            self._row.append(self._cell)
            self._cell = None
        elif tag == "tr":
            self._table.append(self._row)
        elif tag == "caption":
            self._name, self._cap = self._cap, None
        elif tag == "table":
            self.tables[self._name] = self._table
        elif tag == "figcaption":
            self.captions.append(self._fig)
            self._fig = None


def _parse(text: str) -> _Tables:
    parser = _Tables()
    parser.feed(text)
    return parser


def _table(page: _Tables, prefix: str) -> list[list[str]]:
    (name,) = [n for n in page.tables if n.startswith(prefix)]
    return page.tables[name]


def _floats(cells) -> np.ndarray:
    return np.array([np.nan if c == "n/a" else float(c) for c in cells])


# --- fixtures ---
@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return tiny_run(
        tmp_path_factory, [f"results/{SUBJECT}/accuracy.json", "results/cohort/summary.tsv"]
    )


@pytest.fixture(scope="module")
def report(run, tmp_path_factory):
    """The report of the tiny subject with the fit stage's figures, as the rule's script builds it."""
    from scan2morph.render.figures import write_stage_figures

    out = tmp_path_factory.mktemp("report")
    store = run.path("results", SUBJECT, f"{SUBJECT}.h5")
    pngs = write_stage_figures(store, out / "figures", "fit")
    figures = [ReportFigure(p, read_caption(CAPTIONS / f"{p.stem}.rst")) for p in pngs]
    accuracy = json.loads(run.path("results", SUBJECT, "accuracy.json").read_text())
    timings = stage_timings(run.path("benchmarks", "rules"), SUBJECT, ["synth_subject", "ingest"])
    path = out / "report.html"
    page = ReportPage(
        figures=figures,
        accuracy=accuracy,
        timings=timings,
        takes=[t["take"] for t in TAKES],
        n_coordinates=4,
        thumbnail_px=THUMB_PX,
        glb=run.path("results", SUBJECT, f"{SUBJECT}.glb"),
    )
    write_subject_report(path, store, page)
    return path, store, figures, accuracy


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    if CHROMIUM is None:
        pytest.skip("headless Chromium not installed (Debian package 'chromium')")
    b = Browser(tmp_path_factory.mktemp("chromium-profile"))
    yield b
    b.close()


# --- the page in a browser ---
@pytest.mark.slow
@needs_chromium
def test_report_loads_in_chromium_without_errors_and_every_image_renders(report, browser):
    path, _, figures, _ = report
    state = browser.inspect(path.resolve().as_uri())
    assert state["errors"] == []
    assert len(state["images"]) == len(TAKES) + len(figures)
    for img in state["images"]:
        assert img["complete"] and img["width"] > 0 and img["height"] > 0, img
        assert img["data"], img
    # nothing fetched but the viewer's own blob: URLs (the glTF's texture): everything is embedded
    assert [r for r in state["resources"] if not r.startswith("blob:")] == []
    assert state["active"] == 0  # no external script, stylesheet link or frame
    # no script but the viewer's one inline module (none without three.js)
    assert state["scripts"] == (
        []
        if THREE_MISSING
        else [{"type": "module", "src": "", "chars": state["scripts"][0]["chars"]}]
    )


@pytest.mark.slow
@needs_chromium
def test_the_browser_check_catches_broken_images_and_external_resources(report, browser, tmp_path):
    path, *_ = report
    broken = '<img src="data:image/png;base64,AAAA" alt="broken">'
    external = '<img src="http://127.0.0.1:9/x.png" alt="external">'
    bad = tmp_path / "bad.html"
    bad.write_text(path.read_text().replace("</body>", broken + external + "</body>"))
    state = browser.inspect(bad.as_uri())
    assert any("Content Security Policy" in e for e in state["errors"])  # external load blocked
    widths = {i["alt"]: i["width"] for i in state["images"]}
    assert widths["broken"] == 0 and widths["external"] == 0
    assert widths["neutral"] > 0


# --- the 3D viewer ---
VIEWER = "document.getElementById('viewer3d')"


def _viewer_ready(evaluate, timeout: float = 120.0) -> None:
    """Wait until the viewer has loaded the glTF and drawn it (or failed)."""
    deadline = time.monotonic() + timeout
    while (state := evaluate(f"{VIEWER}.dataset.state")) == "loading":
        assert time.monotonic() < deadline, "the viewer did not load in time"
        time.sleep(0.2)
    assert state == "ready", evaluate(f"{VIEWER}.querySelector('.viewer-status').textContent")


def _canvas(evaluate) -> np.ndarray:
    """The viewer's canvas as drawn, (H, W, 3) uint8 RGB."""
    uri = evaluate(f"{VIEWER}.querySelector('canvas').toDataURL('image/png')")
    png = np.frombuffer(base64.b64decode(uri.split(",", 1)[1]), np.uint8)
    return cv2.imdecode(png, cv2.IMREAD_COLOR)[..., ::-1]


def _set(evaluate, name: str, value) -> None:
    """Set a slider or checkbox of the viewer as a user would (with its input/change event)."""
    evaluate(
        f"(() => {{ const e = {VIEWER}.querySelector('input[name={json.dumps(name)}]');"
        f" if (e.type === 'checkbox') {{ e.checked = {json.dumps(bool(value))};"
        " e.dispatchEvent(new Event('change', {bubbles: true})); }"
        f" else {{ e.value = {json.dumps(value)}; e.dispatchEvent(new Event('input', {{bubbles:"
        " true})); } })()"
    )


def _changed(a: np.ndarray, b: np.ndarray) -> int:
    """Pixels that differ by more than 8 levels in some channel."""
    return int((np.abs(a.astype(int) - b.astype(int)).max(axis=2) > 8).sum())


@pytest.mark.slow
@needs_chromium
@needs_three
def test_viewer_controls_change_the_rendered_pixels(report, browser):
    path, store, *_ = report
    with h5py.File(store) as h5:
        visemes = list(h5[paths.VISEMES]) if paths.VISEMES in h5 else []
    names = re.findall(r'<input type="range" data-target="\d+" name="([^"]+)"', path.read_text())
    assert visemes and set(visemes) <= set(names) and {"pca_mean", "pca_1"} <= set(names)

    def act(evaluate, call):
        _viewer_ready(evaluate)
        base = _canvas(evaluate)
        moved = {}
        for name in [*visemes, "pca_1", "mode_1"]:
            _set(evaluate, name, {"pca_1": 3, "mode_1": 0.05}.get(name, 1))
            moved[name] = _changed(base, _canvas(evaluate))
            _set(evaluate, name, 0)
        _click(evaluate, 'button[name="preset-smile1"]')
        moved["preset smile1"] = _changed(base, _canvas(evaluate))
        _click(evaluate, 'button[name="modal-zero"]')
        for take in ("car", "smile1"):
            _pick_take(evaluate, [t["take"] for t in TAKES].index(take))
            moved[f"take {take}"] = _changed(base, _canvas(evaluate))
        _pick_take(evaluate, "")
        back = _canvas(evaluate)
        _set(evaluate, "texture", False)
        untextured = _canvas(evaluate)
        _set(evaluate, "texture", True)
        _set(evaluate, "wireframe", True)
        wire = _canvas(evaluate)
        return base, moved, back, untextured, wire

    state = browser.inspect(path.resolve().as_uri(), act)
    assert state["errors"] == []
    base, moved, back, untextured, wire = state["actions"]
    assert (
        _changed(base, np.full_like(base, (228, 231, 235))) > 0.05 * base[..., 0].size
    )  # a face is drawn
    for name, n in moved.items():
        assert n > 200, (name, n)  # each slider, preset and take changes the face on screen
    assert _changed(base, back) == 0  # every weight back at 0, the model shown: the same picture
    assert _changed(base, untextured) > 1000 and _changed(base, wire) > 1000


@pytest.mark.slow
@needs_chromium
@needs_three
def test_viewer_shows_the_face_upright_from_the_front(report, run, browser, tmp_path):
    """The template's named vertices, as the page placed and projected them, fall on the drawn
    face, forehead above the eyes above the nose tip above the mouth above the chin, the
    subject's left eye on the viewer's right and the nose tip nearest the camera."""
    path, *_ = report
    glb = run.path("results", SUBJECT, f"{SUBJECT}.glb")
    levels = repo_config()["template"]
    template = subdivide_template(build_template(), levels["subdivision_levels"])
    names = ["forehead_centre", "eye_r_outer", "eye_r_inner", "eye_l_inner", "eye_l_outer"]
    names += ["nose_tip", "mouth_r", "mouth_l", "chin"]
    index = [template.named[n] for n in names]

    def act(evaluate, call):
        _viewer_ready(evaluate)
        count = evaluate("window.__viewer.mesh.geometry.attributes.position.count")
        screen = evaluate(
            "(() => { const v = window.__viewer, c = v.renderer.domElement;"
            " const p = v.mesh.geometry.attributes.position;"
            f" return {json.dumps(index)}.map(i => {{ const w = new v.THREE.Vector3()"
            ".fromBufferAttribute(p, i).applyMatrix4(v.mesh.matrixWorld).project(v.camera);"
            " return [(w.x + 1) / 2 * c.width, (1 - w.y) / 2 * c.height, w.z]; }); })()"
        )
        face = _canvas(evaluate)
        evaluate("window.__viewer.mesh.visible = false; window.__viewer.render()")
        empty = _canvas(evaluate)
        evaluate("window.__viewer.mesh.visible = true; window.__viewer.render()")
        shot = call("Page.captureScreenshot", format="png")["data"]
        return count, screen, face, empty, shot

    state = browser.inspect(path.resolve().as_uri(), act)
    assert state["errors"] == []
    count, screen, face, empty, shot = state["actions"]
    (tmp_path / "viewer.png").write_bytes(base64.b64decode(shot))  # for a look when it fails
    assert count == len(template.vertices) == len(read_glb_targets(glb)[0])
    pts = dict(zip(names, np.asarray(screen), strict=True))
    covered = np.abs(face.astype(int) - empty.astype(int)).max(axis=2) > 8
    h, w = covered.shape
    for name, (x, y, _) in pts.items():
        assert 0 <= x < w and 0 <= y < h, (name, x, y)
        r, c = int(y), int(x)
        assert covered[max(r - 2, 0) : r + 3, max(c - 2, 0) : c + 3].any(), name  # on the face
    eyes = np.mean([pts[n][:2] for n in names[1:5]], axis=0)
    mouth = np.mean([pts["mouth_r"][:2], pts["mouth_l"][:2]], axis=0)
    rows = [pts["forehead_centre"][1], eyes[1], pts["nose_tip"][1], mouth[1], pts["chin"][1]]
    assert np.all(np.diff(rows) > 0), rows  # upright: image rows grow downwards
    assert pts["eye_l_outer"][0] > pts["eye_r_outer"][0]  # seen from the front, not mirrored
    assert pts["mouth_l"][0] > pts["mouth_r"][0]
    assert pts["nose_tip"][2] == min(p[2] for p in pts.values())  # nearest the camera
    # the face fills a good part of the canvas, all of it inside
    rs, cs = np.nonzero(covered)
    assert rs.min() > 0 and cs.min() > 0 and rs.max() < h - 1 and cs.max() < w - 1
    assert rs.max() - rs.min() > 0.35 * h


#: Largest difference allowed between a vertex the page draws and the model API's, m (1 um):
#: float32 positions (~1e-8 m at a head's size) plus the page's int16 modal vectors (measured on
#: the tiny run: <= 6e-9 m for the glTF's targets, <= 1e-7 m for modes and presets). The takes
#: are held to half their own quantization step instead.
VIEWER_ATOL_M = 1e-6


def _drawn(evaluate) -> np.ndarray:
    """World positions of every vertex as the page draws them (morphs applied), (V, 3) m."""
    return np.asarray(evaluate("window.__viewer.positions()"), dtype=np.float64).reshape(-1, 3)


def _click(evaluate, selector: str) -> None:
    evaluate(f"{VIEWER}.querySelector({json.dumps(selector)}).click()")


def _pick_take(evaluate, index: int | str) -> None:
    evaluate(
        f"(() => {{ const s = {VIEWER}.querySelector('select[name=take]');"
        f" s.value = {json.dumps(str(index))};"
        " s.dispatchEvent(new Event('change', {bubbles: true})); })()"
    )


@pytest.mark.slow
@needs_chromium
@needs_three
def test_viewer_sliders_and_takes_draw_the_model_api_shapes(report, browser):
    """Semantic sliders (viseme weights, pca_mean and pca_k in sample sigmas), modal sliders and
    expression presets, and each fitted take, read back from the page in head-frame metres,
    against load_model(...).blend / .pca / .expression and the store's aligned meshes."""
    from scan2morph import load_model

    path, store, *_ = report
    model = load_model(store)
    frame = model.head_frame
    head = lambda p: p @ frame[:3, :3].T + frame[:3, 3]  # noqa: E731
    neutral = model.neutral
    q = model.coordinates["smile1"]
    # half of mode 2's slider (its half range moves the mode's largest vertex MODE_PEAK_MM)
    from scan2morph.report.viewer import MODE_PEAK_MM

    q2 = 0.5 * MODE_PEAK_MM / np.linalg.norm(model.modes[1], axis=1).max()
    with h5py.File(store) as h5:
        takes = [t["take"] for t in TAKES]
        aligned = {t: h5[paths.align(t, "vertices")][()] for t in takes}

    def act(evaluate, call):
        _viewer_ready(evaluate)
        got = {"model at rest": _drawn(evaluate)}
        _set(evaluate, "car", 0.5)
        got["car 0.5"] = _drawn(evaluate)
        _set(evaluate, "too", 0.25)
        got["car 0.5 too 0.25"] = _drawn(evaluate)
        _set(evaluate, "car", 0)
        _set(evaluate, "too", 0)
        _set(evaluate, "pca_mean", 1)
        _set(evaluate, "pca_1", 1.5)
        _set(evaluate, "pca_2", -2)
        got["pca 1.5 -2"] = _drawn(evaluate)
        _set(evaluate, "mode_2", q2)
        got["pca + mode 2"] = _drawn(evaluate)
        _click(evaluate, 'button[name="reset"]')
        got["reset"] = _drawn(evaluate)
        _click(evaluate, 'button[name="preset-smile1"]')
        got["smile1 preset"] = _drawn(evaluate)
        _click(evaluate, 'button[name="modal-zero"]')
        for i, take in enumerate(takes):
            _pick_take(evaluate, i)
            faces = evaluate("window.__viewer.mesh.geometry.index.count") // 3
            scale = evaluate(f"window.__viewer.layout.takes[{i}].scale")
            got[take] = (_drawn(evaluate), faces, scale)
        _click(evaluate, 'button[name="next-take"]')  # past the last take: back to the model
        got["after the takes"] = _drawn(evaluate)
        return got

    state = browser.inspect(path.resolve().as_uri(), act)
    assert state["errors"] == []
    got = {k: v if isinstance(v, tuple) else np.asarray(v) for k, v in state["actions"].items()}
    pca = model.pca([1.5, -2.0])
    want = {
        "model at rest": neutral,
        "car 0.5": model.blend({"car": 0.5}),
        "car 0.5 too 0.25": model.blend({"car": 0.5, "too": 0.25}),
        "pca 1.5 -2": pca,
        # the modal displacement adds to the semantic shape
        "pca + mode 2": pca + model.expression([0.0, q2]) - neutral,
        "reset": neutral,
        "smile1 preset": model.expression(q),  # all 10 coordinates: 4 sliders + the rest
        "after the takes": neutral,
    }
    for name, shape in want.items():
        err = np.abs(got[name] - head(shape)).max()
        assert err < VIEWER_ATOL_M, (name, err)
        assert (
            name == "model at rest"
            or name in ("reset", "after the takes")
            or (np.abs(head(shape) - head(neutral)).max() > 1e-3)
        ), name  # each of these moves the face by more than 1 mm
    faces = model.faces
    for take in takes:
        drawn, n_faces, scale = got[take]
        valid = np.isfinite(aligned[take]).all(axis=1)
        assert 0.5 * len(valid) < valid.sum() < len(valid)  # some invalid vertices to hide
        err = np.abs(np.asarray(drawn)[valid] - head(aligned[take][valid])).max()
        # half a quantization step of the take's motion (its largest / 65534) plus float32
        # rounding; on the tiny run 0.45-0.53 um for steps of 0.9-1.1 um
        assert err <= 0.5 * scale + 2e-8, (take, err, scale)
        assert n_faces == int(valid[faces].all(axis=1).sum())  # faces on invalid vertices hidden


@pytest.fixture(scope="module")
def bare_subject(report, run, tmp_path_factory):
    """The tiny subject as a subject with the neutral take only would be stored (no visemes:
    no /visemes, /pca, blends, click-noise; no expressions: no /expressions; /skipped says so,
    with the stages' own words) and its neutral-only glTF, and its report page."""
    from scan2morph import load_model
    from scan2morph.io import write_glb
    from scan2morph.stages.modal import NO_EXPRESSIONS
    from scan2morph.stages.morph import NO_VISEMES

    _, store, *_ = report
    out = tmp_path_factory.mktemp("bare")
    bare = out / "bare.h5"
    shutil.copy(store, bare)
    with h5py.File(bare, "a") as h5:
        for group in ("visemes", "pca", "blends", "pca_blends", "motion_noise", "expressions"):
            if group in h5:
                del h5[group]
        for take in ("car", "too", "smile1"):
            del h5[paths.take(take)]
        skipped = h5.require_group(paths.SKIPPED)
        skipped.attrs["morph"] = NO_VISEMES
        skipped.attrs["modal_coordinates"] = NO_EXPRESSIONS
    model = load_model(bare)
    glb = out / "bare.glb"
    mesh = TexturedMesh(model.neutral, model.faces, model.uv, model.texture)
    write_glb(glb, mesh, frame=model.head_frame)
    page = out / "report.html"
    write_subject_report(page, bare, ReportPage(versions={}, glb=glb, n_coordinates=4))
    return page, model


@pytest.mark.slow
@needs_three
def test_viewer_of_a_subject_without_visemes_or_expressions_says_what_is_missing(bare_subject):
    page, _ = bare_subject
    text = page.read_text()
    missing = re.search(r'<ul class="missing">(.*?)</ul>', text, re.S)[1]
    for line in (
        "No viseme sliders: the subject has no viseme models.",
        "No PCA sliders: the subject has no PCA (it needs viseme takes).",
        "No expression presets: the subject has no expression takes.",
        "morph: no viseme takes: no blend shapes or PCA",
        "modal_coordinates: no expression takes",
    ):
        assert line in missing, line
    assert "data-target=" not in text and "data-preset=" not in text
    assert "No semantic sliders: the glTF has no morph targets." in text
    assert len(re.findall(r'data-mode="\d+"', text)) == 4


@pytest.mark.slow
@needs_chromium
@needs_three
def test_viewer_of_a_subject_without_visemes_or_expressions_works(bare_subject, browser):
    page, model = bare_subject
    frame = model.head_frame
    head = lambda p: p @ frame[:3, :3].T + frame[:3, 3]  # noqa: E731

    def act(evaluate, call):
        _viewer_ready(evaluate)
        base = _canvas(evaluate)
        # half the slider's range: the mode's largest vertex moves 5 mm (MODE_PEAK_MM / 2)
        q = 0.5 * float(evaluate(f"{VIEWER}.querySelector('input[name=mode_1]').max"))
        _set(evaluate, "mode_1", q)
        moved, drawn = _canvas(evaluate), _drawn(evaluate)
        options = evaluate(
            f"Array.from({VIEWER}.querySelectorAll('select[name=take] option'), o => o.text)"
        )
        _click(evaluate, 'button[name="next-take"]')
        return base, moved, drawn, options, _drawn(evaluate), q

    state = browser.inspect(page.resolve().as_uri(), act)
    assert state["errors"] == []
    base, moved, drawn, options, neutral_take, q = state["actions"]
    assert _changed(np.asarray(base, np.uint8), np.asarray(moved, np.uint8)) > 200
    err = np.abs(np.asarray(drawn) - head(model.expression([q]))).max()
    assert err < VIEWER_ATOL_M, err
    assert options == ["model (the sliders below)", "neutral: neutral"]
    assert np.isfinite(neutral_take).all()


@pytest.mark.slow
@needs_three
def test_viewer_of_a_glb_without_its_frame_keeps_its_sliders_and_says_why(report, run, tmp_path):
    """A .glb written before the head frame (no node.extras.source_to_gltf): the page keeps its
    morph-target sliders and says why the modes and takes are not shown."""
    import pygltflib

    _, store, *_ = report
    gltf = pygltflib.GLTF2.load(run.path("results", SUBJECT, f"{SUBJECT}.glb"))
    for node in gltf.nodes:
        node.extras = {}
    old = tmp_path / "old.glb"
    gltf.save_binary(str(old))
    text = subject_report_html(store, ReportPage(versions={}, glb=old, n_coordinates=4))
    missing = re.search(r'<ul class="missing">(.*?)</ul>', text, re.S)[1]
    assert "No modal sliders or fitted takes: old.glb does not say its frame" in missing
    assert "data-mode=" not in text and '<select name="take">' not in text
    assert {"car", "too", "pca_mean", "pca_1"} <= set(
        re.findall(r'data-target="\d+" name="(\w+)"', text)
    )


@pytest.mark.slow
def test_viewer_script_is_the_one_the_policy_allows(report):
    path, *_ = report
    text = path.read_text()
    policy = re.search(r'http-equiv="Content-Security-Policy" content="([^"]+)"', text)[1]
    policy = html.unescape(policy)  # the template escapes the quotes of 'sha256-...'
    scripts = re.findall(r"<script([^>]*)>(.*?)</script>", text, re.S)
    if THREE_MISSING:
        assert scripts == [] and "script-src" not in policy
        assert "No 3D viewer: three.js is not installed" in text
        pytest.skip(THREE_MISSING)
    ((attrs, code),) = scripts
    assert attrs == ' type="module"'
    directives = dict(d.strip().split(" ", 1) for d in policy.split(";"))
    assert directives["default-src"] == "'none'"
    assert directives["script-src"] == script_hash(code)
    assert "http" not in policy and "unsafe-eval" not in policy
    assert re.search(r"^\s*(import|export)\b", code, re.M) is None  # one bundled module


@pytest.mark.slow
def test_report_without_three_says_why(report, run, tmp_path):
    _, store, *_ = report
    glb = run.path("results", SUBJECT, f"{SUBJECT}.glb")
    text = subject_report_html(
        store, ReportPage(versions={}, glb=glb, three_dir=tmp_path / "three")
    )
    assert "No 3D viewer: three.js is not installed" in text and "make setup" in text
    assert "<script" not in text and "script-src" not in text
    text = subject_report_html(store, ReportPage(versions={}, glb=tmp_path / "absent.glb"))
    assert "No 3D viewer: absent.glb was not written" in text and "<script" not in text


def test_the_viewer_bundle_is_esbuilds_one_module_or_a_reason(tmp_path):
    """The report inlines the bundle esbuild wrote at setup: one module, no import left, that
    runs; a missing or stale bundle, or one that would end the inline script, says why."""
    if THREE_MISSING:
        pytest.skip(THREE_MISSING)
    code = viewer_script()
    assert re.search(r"^\s*(import|export)\b", code, re.M) is None
    assert "Copyright 2010-2024 Three.js Authors" in code  # three.js's licence kept
    node = shutil.which("node")
    if node is not None:  # it parses as a module (it needs a browser to run)
        subprocess.run(
            [node, "--check", "--input-type=module", "-"], input=code, text=True, check=True
        )
    three = VIEWER_BUNDLE.parents[1] / "node_modules" / "three"
    missing = three_unavailable(three, tmp_path / "viewer.js")
    assert "viewer bundle" in missing and "missing" in missing and "make setup" in missing
    stale = tmp_path / "stale.js"
    stale.write_text("1;")
    os.utime(stale, ns=(1, 1))
    assert "older than" in three_unavailable(three, stale)
    assert "three.js is not installed" in three_unavailable(tmp_path / "three", stale)
    bad = tmp_path / "bad.js"
    bad.write_text("const s = '</script>';\n")
    with pytest.raises(InputError, match="</script"):
        viewer_script(bad)


# --- the page's content against its sources ---
@pytest.mark.slow
def test_pca_tables_match_the_store(report):
    path, store, *_ = report
    page = _parse(path.read_text())
    t1, t2 = _table(page, "Table 1"), _table(page, "Table 2")
    with h5py.File(store) as h5:
        eig, cr, ccr = (h5[paths.pca(k)][()] for k in ("eigenvalues", "cr", "ccr"))
        coeff, names = h5[paths.pca("coefficients")][()], h5[paths.pca("takes")].asstr()[()]
    body = np.array([_floats(r) for r in t1[1:]])
    np.testing.assert_array_equal(body[:, 0], np.arange(1, len(eig) + 1))
    np.testing.assert_allclose(body[:, 1], eig, rtol=1e-3)
    np.testing.assert_allclose(body[:, 2:], 100 * np.c_[cr, ccr], rtol=1e-3)
    assert t2[0] == ["model", *[f"w{i + 1}" for i in range(coeff.shape[1])]]
    assert [r[0] for r in t2[1:]] == list(names)
    np.testing.assert_allclose(np.array([_floats(r[1:]) for r in t2[1:]]), coeff, rtol=1e-3)


@pytest.mark.slow
def test_click_noise_table_matches_the_store(report):
    path, store, *_ = report
    table = _table(_parse(path.read_text()), "Error that landmark clicks")
    with h5py.File(store) as h5:
        names = h5[paths.motion_noise("takes")].asstr()[()]
        err = h5[paths.motion_noise("rms_error_mm")][()]
        rel = h5[paths.motion_noise("relative")][()]
        failed = h5[paths.motion_noise("failed_draws")][()]
    assert table[0] == ["viseme", "click-noise error (mm)", "of the motion (%)", "refits refused"]
    assert [r[0] for r in table[1:]] == list(names)
    body = np.array([_floats(r[1:]) for r in table[1:]])
    np.testing.assert_allclose(body, np.c_[err, 100 * rel, failed], rtol=1e-3)


@pytest.mark.slow
def test_modal_tables_match_the_store(report):
    path, store, *_ = report
    page = _parse(path.read_text())
    coords, recon = _table(page, "Modal coordinates"), _table(page, "RMS error")
    # "Natural frequencies", or with coordinates "vertex" "Frequencies (Rayleigh quotients, ..."
    (name,) = [n for n in page.tables if re.match(r"(Natural f|F)requencies.* of the first", n)]
    freqs = page.tables[name]
    with h5py.File(store) as h5:
        q = h5[paths.expression("smile1", "coordinates")][()]
        ks = h5[paths.modal("reconstruction_k")][()]
        f = h5[paths.modal("frequencies_hz")][()]
    assert coords[0] == ["expression", "q1", "q2", "q3", "q4"]
    assert coords[1][0] == "smile1 (smile)"
    np.testing.assert_allclose(_floats(coords[1][1:]), q[:4], rtol=1e-3)
    np.testing.assert_allclose(_floats(freqs[1][1:]), f[:4], rtol=1e-3)
    assert recon[0][1 : 2 + len(ks)] == ["part", *[f"K = {k}" for k in ks]]
    assert [r[:2] for r in recon[1:4]] == [["smile1 (smile)", p] for p in PARTS]
    with h5py.File(store) as h5:
        for row, key in zip(recon[1:4], RECONSTRUCTION_KEYS, strict=True):
            want = h5[paths.expression("smile1", key)][()]
            np.testing.assert_allclose(_floats(row[2 : 2 + len(ks)]), want, rtol=1e-3)
        to_target = h5[paths.expression("smile1", "modes_to_target")][()]
        target = h5[paths.modal("reconstruction_target_mm")][()]
    assert recon[0][-1] == f"modes for <= {target:g} mm"
    np.testing.assert_allclose(_floats([recon[1][-1]]), [to_target])
    total, normal, tangential = (_floats(r[2 : 2 + len(ks)]) for r in recon[1:4])
    np.testing.assert_allclose(total**2, normal**2 + tangential**2, rtol=2e-3)


@pytest.mark.slow
def test_accuracy_and_provenance_match_their_sources(report, run):
    path, store, _, accuracy = report
    page = _parse(path.read_text())
    summary = {r[0]: r[2] for r in _table(page, "Summary: each measure")[1:]}
    numbers = {k: v for k, v in accuracy["summary"].items() if isinstance(v, (int, float))}
    assert numbers.keys() <= summary.keys()
    for key, value in numbers.items():
        assert float(summary[key]) == pytest.approx(value, rel=1e-3)
    _assert_material_tables(page, accuracy)
    text = path.read_text()
    assert text.index('id="accuracy"') < text.index('id="inputs"')  # the headline leads
    per_take = _table(page, "Per take")
    assert [r[0] for r in per_take[1:]] == list(accuracy["takes"])
    column = per_take[0].index("mesh rms_mm")
    for row in per_take[1:]:
        assert float(row[column]) == pytest.approx(
            accuracy["takes"][row[0]]["mesh"]["rms_mm"], rel=1e-3
        )
    attrs = dict(_table(page, "Store")[1:])
    with h5py.File(store) as h5:
        assert attrs["config_sha256"] == h5.attrs["config_sha256"]
        assert attrs["format_version"] == h5.attrs["format_version"]
        checksums = json.loads(h5.attrs["input_sha256"])
    rows = _table(page, "Input checksums")[1:]
    assert {(t, r): h for t, r, h in rows} == {
        (t, r): h for t, roles in checksums.items() for r, h in roles.items()
    }
    versions = dict(_table(page, "Software")[1:])
    assert versions["numpy"] == np.__version__
    assert versions["h5py"] == h5py.__version__
    assert versions["python"] == sys.version.split()[0]
    # run time: the sum of the benchmark files' `s`, read here with the csv module
    files = sorted(run.path("benchmarks", "rules").glob(f"*/{SUBJECT}.tsv")) + sorted(
        run.path("benchmarks", "rules").glob(f"*/{SUBJECT}/*.tsv")
    )
    total = 0.0
    for f in files:
        with f.open() as fh:
            total += float(next(csv.DictReader(fh, delimiter="\t"))["s"])
    timing = _table(page, "Run time")
    assert timing[-1][0] == "total"
    assert float(timing[-1][2]) == pytest.approx(total, rel=1e-3)
    assert [r[0] for r in timing[1:3]] == ["synth_subject", "ingest"]  # the order given
    assert int(timing[-1][1]) == len(files)


@pytest.mark.slow
def test_inputs_are_thumbnails_of_the_color_images(report):
    path, store, figures, _ = report
    page = _parse(path.read_text())
    thumbs = [i for i in page.images if i["src"].startswith("data:image/jpeg;base64,")]
    assert [i["alt"] for i in thumbs] == [t["take"] for t in TAKES]
    with h5py.File(store) as h5:
        color = h5[paths.range_image("car", "color")][()]
    car = next(i for i in thumbs if i["alt"] == "car")
    data = np.frombuffer(base64.b64decode(car["src"].split(",", 1)[1]), np.uint8)
    got = cv2.imdecode(data, cv2.IMREAD_COLOR)[..., ::-1]
    h, w = color.shape[:2]
    want = cv2.resize(color, (THUMB_PX, round(h * THUMB_PX / w)), interpolation=cv2.INTER_AREA)
    assert got.shape == want.shape == (60, 80, 3)
    assert np.abs(got.astype(float) - want).mean() < 3.0  # JPEG quality 85


@pytest.mark.slow
def test_figures_are_embedded_byte_for_byte_with_their_captions(report):
    path, _, figures, _ = report
    page = _parse(path.read_text())
    embedded = {i["alt"]: i["src"] for i in page.images if i["src"].startswith("data:image/png")}
    assert list(embedded) == [f.path.stem for f in figures]
    for fig in figures:
        assert base64.b64decode(embedded[fig.path.stem].split(",", 1)[1]) == fig.path.read_bytes()
        assert f"{fig.path.stem}: {fig.caption}" in page.captions
        assert fig.caption == " ".join((CAPTIONS / f"{fig.path.stem}.rst").read_text().split())


@pytest.mark.slow
def test_text_is_escaped(report, tmp_path):
    _, store, figures, _ = report
    nasty = '<script>alert("x")</script> & <b>'
    text = subject_report_html(
        store, ReportPage(figures=[ReportFigure(figures[0].path, nasty)], versions={})
    )
    assert "<script" not in text
    # Jinja2's autoescape (markupsafe) writes the double quote as &#34;
    assert "&lt;script&gt;alert(&#34;x&#34;)&lt;/script&gt; &amp; &lt;b&gt;" in text
    assert f"{figures[0].path.stem}: {nasty}" in _parse(text).captions  # the same text, shown
    flat = subject_report_html(
        store, ReportPage(accuracy={"summary": {"<i>": 1.0}}, versions={"a<b": "c&d"})
    )
    assert "&lt;i&gt;" in flat and "a&lt;b" in flat and "c&amp;d" in flat and "<i>" not in flat


@pytest.mark.slow
def test_report_without_figures_or_ground_truth_says_so(report):
    _, store, *_ = report
    text = subject_report_html(store, ReportPage(versions={}))
    assert "No figures were drawn for this subject." in text
    assert "No ground truth" in text
    assert "No benchmark files were found" in text


# --- unit tests ---
def test_each_table_shows_its_column_dictionary():
    """Under each table with a TSV twin: a folded dictionary of the TSV's columns (issue #19)."""
    from scan2morph import tables
    from scan2morph.report import html as report_html
    from scan2morph.report import sections

    with h5py.File("sections.h5", "w", driver="core", backing_store=False) as h5:
        h5[paths.pca("eigenvalues")] = [4.0, 1.0]
        h5[paths.pca("cr")], h5[paths.pca("ccr")] = [0.8, 0.2], [0.8, 1.0]
        h5[paths.pca("coefficients")] = np.ones((3, 2))
        h5[paths.pca("takes")] = np.array(["neutral", "car", "too"], dtype=object)
        h5[paths.motion_noise("takes")] = np.array(["car"], dtype=object)
        h5[paths.motion_noise("relative")], h5[paths.motion_noise("rms_error_mm")] = [0.1], [0.5]
        h5[paths.motion_noise("failed_draws")] = [0]
        h5[paths.modal("frequencies_hz")] = [10.0, 20.0]
        h5[paths.modal("reconstruction_k")] = [1, 2]
        h5[paths.expression("smile1", "coordinates")] = [0.5, 0.25]
        h5[paths.expression("smile1", "reconstruction_rms_mm")] = [1.0, 0.5]
        text = report_html.render_blocks(
            sections.pca(h5) + sections.motion_noise(h5) + sections.modal(h5, 2)
        )
    page = _parse(text)
    for name, dictionary in {
        "pca_eigenvalues": tables.PCA_EIGENVALUES,
        "pca_coefficients": tables.PCA_COEFFICIENTS,
        "motion_noise": tables.MOTION_NOISE,
        "modal_coordinates": tables.MODAL_COORDINATES,
        "modal_reconstruction": tables.MODAL_RECONSTRUCTION,
    }.items():
        assert f"<summary>Columns of tables/{name}.tsv</summary>" in text
        rows = _table(page, f"Column dictionary: {name}.tsv")
        assert rows[0] == ["column", "unit", "definition"]
        assert rows[1:] == [[c.name, c.unit, c.definition] for c in dictionary]
    assert text.count("<details") == text.count("</details>") == 5


PARTS = ("total", "normal", "tangential")
RECONSTRUCTION_KEYS = (
    "reconstruction_rms_mm",
    "reconstruction_normal_rms_mm",
    "reconstruction_tangential_rms_mm",
)
MATERIAL, IDEAL = report_accuracy.MATERIAL_KEYS, report_accuracy.IDEAL_KEYS


def _assert_material_tables(page, accuracy):
    """The accuracy section's first tables show accuracy.json's material and method-ideal
    errors of each viseme and the material errors of each expression (% and mm)."""
    visemes = _table(page, "Viseme motion: error against the material motion")
    assert visemes[0] == report_accuracy.MATERIAL_COLUMNS
    assert all(c.endswith(("(mm)", "(% of the motion)")) for c in visemes[0][2:])  # units stated
    want = [t for t, e in accuracy["takes"].items() if "motion" in e]
    assert [r[0] for r in visemes[1:]] == [t for t in want for _ in range(2)]
    for i, take in enumerate(want):
        entry = accuracy["takes"][take]["motion"]
        for row, keys, what in (
            (visemes[1 + 2 * i], MATERIAL, "material motion"),
            (visemes[2 + 2 * i], IDEAL, "method-ideal motion"),
        ):
            assert row[1] == what
            values = [np.nan if entry[k] is None else entry[k] for k in keys]
            values[0] *= 100
            np.testing.assert_allclose(_floats(row[2:]), values, rtol=1e-3)
    exprs = [t for t, e in accuracy["takes"].items() if "expression" in e]
    if exprs:
        table = _table(page, "Expression displacement fields")
        assert [r[0] for r in table[1:]] == exprs
        for row, take in zip(table[1:], exprs, strict=True):
            values = [accuracy["takes"][take]["expression"][k] for k in MATERIAL]
            values[0] *= 100
            np.testing.assert_allclose(_floats(row[2:]), values, rtol=1e-3)


def test_accuracy_section_leads_with_the_material_error():
    from scan2morph.report import html as report_html

    def motion(scale):
        return {k: scale * (i + 1) for i, k in enumerate((*MATERIAL, *IDEAL))} | {
            "masked_true_motion_share": 0.001
        }

    accuracy = {
        "summary": {"motion_material_relative_error_max": 0.5},
        "takes": {
            "neutral": {"mesh": {"rms_mm": 0.1}},
            "car": {"mesh": {"rms_mm": 0.1}, "motion": motion(0.1234567)},
            "too": {"motion": motion(0.02) | {"material_normal_rms_error_mm": None}},
            "smile1": {"expression": {k: 0.3 * (i + 2) for i, k in enumerate(MATERIAL)}},
        },
    }
    text = report_html.render_blocks(report_accuracy.accuracy(accuracy))
    page = _parse(text)
    names = list(page.tables)
    assert names[0].startswith("Viseme motion: error against the material motion")
    assert names[1].startswith("Expression displacement fields")
    _assert_material_tables(page, accuracy)
    # a value accuracy.json lacks (null) shows as n/a; 4 significant digits, percent
    too = _table(page, "Viseme motion")[3]
    assert too[:3] == ["too", "material motion", "2"] and too[4] == "n/a"
    assert _table(page, "Viseme motion")[1][2] == "12.35"
    # no material entries (an older accuracy.json): no headline tables, the rest stays
    old = report_accuracy.accuracy(
        {"summary": {"x": 1.0}, "takes": {"car": {"mesh": {"rms_mm": 1}}}}
    )
    assert [b["table"]["caption"] for b in old if b["kind"] == "table"] == [
        report_accuracy.SUMMARY_CAPTION,
        "Per take",
    ]


def test_modal_section_splits_the_reconstruction_and_shows_the_outline():
    from scan2morph.report import html as report_html

    with h5py.File("modal.h5", "w", driver="core", backing_store=False) as h5:
        h5[paths.modal("frequencies_hz")] = [10.0, 20.0]
        h5[paths.modal("reconstruction_k")] = [1, 2]
        h5[paths.modal("reconstruction_target_mm")] = 0.5
        fixed, outline = np.zeros(8, bool), np.zeros(8, bool)
        outline[:6], fixed[:4] = True, True
        h5[paths.modal("fixed_vertices")], h5[paths.modal("outline_vertices")] = fixed, outline
        parts = {
            "e1": ([3.0, 0.4], [1.0, 0.3], [2.0, 0.2], 2.0),
            "e2": ([5.0, 4.0], *[[3, 2.5]] * 2, np.nan),
        }
        for take, (total, normal, tangential, reach) in parts.items():
            h5[paths.expression(take, "coordinates")] = [0.5, 0.25]
            for key, values in zip(RECONSTRUCTION_KEYS, (total, normal, tangential), strict=True):
                h5[paths.expression(take, key)] = values
            h5[paths.expression(take, "modes_to_target")] = reach
            h5[paths.expression(take, "outline_rms_mm")] = 1.5
            h5[paths.expression(take, "clamped_rms_mm")] = 0.25
        h5[paths.take("e1")] = np.zeros(1)
        h5[paths.take("e1")].attrs["label"] = "smile"
        page = _parse(report_html.render_blocks(sections.modal(h5, 2)))
    recon = _table(page, "RMS error")
    assert recon[0] == ["expression", "part", "K = 1", "K = 2", "modes for <= 0.5 mm"]
    assert recon[1:] == [
        ["e1 (smile)", "total", "3", "0.4", "2"],
        ["e1 (smile)", "normal", "1", "0.3", "n/a"],
        ["e1 (smile)", "tangential", "2", "0.2", "n/a"],
        ["e2", "total", "5", "4", "n/a"],  # NaN: no K of the basis reaches the target
        ["e2", "normal", "3", "2.5", "n/a"],
        ["e2", "tangential", "3", "2.5", "n/a"],
    ]
    rim = _table(page, "Displacement on the face's outline")
    caption = next(n for n in page.tables if n.startswith("Disp"))
    assert "6 outline vertices, 4 clamped" in caption and "strip" not in caption
    assert rim[1:] == [["e1 (smile)", "1.5", "0.25"], ["e2", "1.5", "0.25"]]
    # the skin preset holds the rest of the outline by the skin beyond it: the caption says so
    with h5py.File("modal.h5", "w", driver="core", backing_store=False) as h5:
        h5[paths.modal("reconstruction_k")] = [1, 2]
        h5[paths.modal("fixed_vertices")], h5[paths.modal("outline_vertices")] = fixed, outline
        h5[paths.modal("physics")] = json.dumps({"preset": "skin", "outline_strip_mm": 6.0})
        h5[paths.expression("e1", "outline_rms_mm")] = 1.5
        h5[paths.expression("e1", "clamped_rms_mm")] = 0.25
        caption = _parse(report_html.render_blocks(sections._outline(h5, ["e1"], {"e1": ""})))
    (caption,) = [n for n in caption.tables if n.startswith("Disp")]
    assert "4 clamped" in caption and "the other 2 are held by the skin beyond the" in caption
    assert "a strip 6 mm wide" in caption


def test_modal_frequency_caption_says_when_they_are_rayleigh_quotients():
    """Audit 12: with coordinates "vertex" (the skin preset) the stored frequencies are Rayleigh
    quotients of the vertex-orthonormalised modes, out of order (205, 277, 278, 215 Hz): the
    table called them "Natural frequencies"."""
    from scan2morph.report import html as report_html

    def caption(physics):
        with h5py.File("modal.h5", "w", driver="core", backing_store=False) as h5:
            h5[paths.modal("frequencies_hz")] = [205.0, 277.1, 215.3]
            if physics is not None:
                h5[paths.modal("physics")] = json.dumps(physics)
            page = _parse(report_html.render_blocks(sections.modal(h5, 3)))
        (name,) = [n for n in page.tables if "of the first 3 of 3 modes" in n]
        return name

    vertex = caption({"preset": "skin", "coordinates": "vertex"})
    assert vertex.startswith("Frequencies (Rayleigh quotients, not in ascending order")
    assert "Natural frequencies" not in vertex
    assert caption({"preset": "paper", "coordinates": "mass"}).startswith("Natural frequencies")
    assert caption(None).startswith("Natural frequencies")


def test_viewer_data_decodes_to_the_store_within_half_a_step():
    """The viewer's binary block, decoded as the page does (int16 * scale, -32768 = invalid),
    gives the modes, the expressions' remaining modes and the aligned takes in the glTF frame."""
    from scan2morph.report.viewer import INVALID, viewer_data

    rng = np.random.default_rng(3)
    n_v, k = 40, 3
    rot, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    rot *= np.sign(np.linalg.det(rot))
    frame = np.eye(4)
    frame[:3, :3], frame[:3, 3] = 1e-3 * rot, [0.1, -0.2, 0.3]
    neutral = rng.normal(scale=50.0, size=(n_v, 3))
    modes = rng.normal(scale=100.0, size=(k, n_v, 3))
    q = np.array([0.01, -0.02, 0.005])
    aligned = neutral + rng.normal(scale=3.0, size=(n_v, 3))
    aligned[[2, 7]] = np.nan
    with h5py.File("viewer.h5", "w", driver="core", backing_store=False) as h5:
        h5[paths.neutral("vertices")] = neutral
        h5[paths.modal("modes")], h5[paths.modal("frequencies_hz")] = modes, [1.0, 2.0, 3.0]
        h5[paths.expression("smile1", "coordinates")] = q
        h5[paths.align("car", "vertices")], h5[paths.align("car", "ok")] = aligned, False
        h5[paths.take("car")].attrs.update(kind="viseme", label="car")
        h5.require_group(paths.take("smile1")).attrs.update(kind="expression", label="smile")
        layout, block = viewer_data(h5, ["car"], n_modes=2, frame=frame)

    def decoded(entry):
        steps = np.frombuffer(block, "<i2", 3 * n_v, entry["offset"]).reshape(n_v, 3)
        return np.where(steps == INVALID, np.nan, steps * entry["scale"]), entry["scale"]

    expected = [modes[0] @ frame[:3, :3].T, modes[1] @ frame[:3, :3].T]
    expected.append((q[2] * modes[2]) @ frame[:3, :3].T)  # smile1's mode beyond the sliders
    expected.append((aligned - neutral) @ frame[:3, :3].T)
    entries = [*layout["modes"], layout["presets"][0]["rest"], layout["takes"][0]]
    for entry, want in zip(entries, expected, strict=True):
        got, scale = decoded(entry)
        np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
        assert scale == pytest.approx(np.nanmax(np.abs(want)) / 32767)
        assert np.nanmax(np.abs(got - want)) <= 0.5 * scale * (1 + 1e-9)
    assert len(block) == 4 * n_v * 3 * 2
    assert [m["mode"] for m in layout["modes"]] == [1, 2]
    assert layout["presets"][0] | {"rest": None} == {
        "take": "smile1",
        "label": "smile",
        "q": q[:2].tolist(),
        "modes": 3,
        "rest": None,
    }
    for i, m in enumerate(layout["modes"]):
        peak = np.linalg.norm(modes[i], axis=1).max()
        assert m["range"] == pytest.approx(max(10.0 / peak, 1.25 * abs(q[i])))
    take = layout["takes"][0]
    assert (take["take"], take["kind"], take["valid"], take["aligned"]) == (
        "car",
        "viseme",
        38,
        False,
    )


def test_read_caption_strips_inline_markup(tmp_path):
    f = tmp_path / "c.rst"
    f.write_text("The ``q`` field,\n  *emphasised* and **strong**, see `Eq. 7`_.\n")
    assert read_caption(f) == "The q field, emphasised and strong, see Eq. 7."
    with pytest.raises(InputError, match="caption file not found"):
        read_caption(tmp_path / "none.rst")


def test_image_uri_rejects_bad_figures(tmp_path):
    png = tmp_path / "a.png"
    ok, buf = cv2.imencode(".png", np.zeros((4, 5, 3), np.uint8))
    png.write_bytes(buf.tobytes())
    assert image_uri(png) == "data:image/png;base64," + base64.b64encode(buf.tobytes()).decode()
    (tmp_path / "b.gif").write_bytes(b"GIF89a")
    with pytest.raises(InputError, match=r"figure: expected one of \['.jpeg', '.jpg', '.png'\]"):
        image_uri(tmp_path / "b.gif")
    (tmp_path / "c.png").write_bytes(b"\xff\xd8\xff\xe0 jpeg bytes")
    with pytest.raises(InputError, match="not a image/png file"):
        image_uri(tmp_path / "c.png")
    with pytest.raises(InputError, match="figure file not found"):
        image_uri(tmp_path / "missing.png")


def test_thumbnail_keeps_aspect_and_small_images():
    rng = np.random.default_rng(8)
    img = rng.integers(0, 256, (90, 200, 3), dtype=np.uint8)
    small = cv2.imdecode(np.frombuffer(thumbnail_jpeg(img, 100), np.uint8), cv2.IMREAD_COLOR)
    assert small.shape == (45, 100, 3)
    same = cv2.imdecode(np.frombuffer(thumbnail_jpeg(img, 400), np.uint8), cv2.IMREAD_COLOR)
    assert same.shape == img.shape
    with pytest.raises(InputError, match=r"color: expected \(H, W, 3\) uint8"):
        thumbnail_jpeg(img.astype(np.float32), 100)


def test_stage_timings_sum_the_benchmark_files(tmp_path):
    head = "s\th:m:s\tmax_rss\n"
    (tmp_path / "fit" / "alice").mkdir(parents=True)
    (tmp_path / "fit" / "alice" / "car.tsv").write_text(head + "2.5\t0:00:02\t100\n")
    (tmp_path / "fit" / "alice" / "neutral.tsv").write_text(head + "1.25\t0:00:01\t300\n")
    (tmp_path / "fit" / "bob.tsv").write_text(head + "9\t0:00:09\t1\n")  # another subject
    (tmp_path / "store").mkdir()
    (tmp_path / "store" / "alice.tsv").write_text(head + "0.5\t0:00:00\t50\n")
    rows = stage_timings(tmp_path, "alice", order=["store", "fit"])
    assert rows == [
        {"stage": "store", "jobs": 1, "seconds": 0.5, "max_rss_mb": 50.0},
        {"stage": "fit", "jobs": 2, "seconds": 3.75, "max_rss_mb": 300.0},
    ]
    assert stage_timings(tmp_path / "none", "alice") == []
    (tmp_path / "store" / "alice.tsv").write_text("x\n1\n")
    with pytest.raises(InputError, match="expected a TSV with a column 's'"):
        stage_timings(tmp_path, "alice")


def test_software_versions_name_missing_packages():
    v = software_versions({"numpy": ("numpy",), "ghost": ("no-such-distribution-xyz",)})
    assert v["numpy"] == np.__version__
    assert v["ghost"] == "not installed"
    assert list(v)[:3] == ["python", "platform", "scan2morph"]


# --- the workflow ---
def _snakemake(run, *args) -> subprocess.CompletedProcess:
    cmd = [
        str(Path(sys.executable).with_name("snakemake")),
        *args,
        "-s",
        str(REPO / "Snakefile"),
        "-d",
        str(run.work),
        "--configfile",
        *map(str, run.configfiles),
    ]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_report_rule_takes_every_figure_and_the_accuracy(run):
    res = _snakemake(run, f"results/{SUBJECT}/report.html", "-n", "-F", "--quiet", "rules")
    assert res.returncode == 0, res.stderr
    rules = {line.split()[0] for line in res.stdout.splitlines() if line.strip()}
    # one job runs the synthetic subject's own stages: the store, accuracy, figures and report
    assert "subject_synthetic" in rules
    assert "cohort" not in rules


@pytest.mark.slow
def test_snakemake_report_builds(run, tmp_path):
    out = tmp_path / "workflow_report.html"
    res = _snakemake(run, "results/cohort/summary.tsv", "--report", str(out))
    assert res.returncode == 0, res.stderr
    text = out.read_text()
    for category in ("Cohort", "Accuracy", "Morphable model"):
        assert category in text
    caption = " ".join((REPO / "workflow" / "report" / "cohort_table.rst").read_text().split())
    assert caption[:60] in text


@pytest.mark.slow  # the tiny run's finished products
def test_the_page_links_its_products_and_keeps_the_navigation_in_view(report, run):
    path, _, _, _ = report
    text = path.read_text()
    hrefs = re.findall(r'<p class="files">(.*?)</p>', text)[0]
    for product in (f"{SUBJECT}.h5", f"{SUBJECT}.glb", "meshes/", "tables/", "accuracy.json"):
        assert f'href="{product}"' in hrefs
        # relative to the page, as the workflow places it in results/{subject}/
        assert run.path("results", SUBJECT, product.rstrip("/")).exists(), product
    assert (
        "nav{position:sticky" in text
        and "white-space:nowrap}" not in text.split("caption{")[1][:80]
    )
    assert text.index('id="status"') < text.index('id="inputs"')  # warnings come first


def test_a_takes_caption_says_how_its_correspondence_was_made(tmp_path):
    """Refined by its texture, by its shape (and registered to the others by the takes'
    consensus), or its template fit kept; nothing for a take without a verdict (the neutral)."""
    from scan2morph.report.sections import correspondence
    from scan2morph.store import write_part

    store = tmp_path / "s.h5"
    attrs = {
        paths.refine_group("car"): {"used": True, "shape_used": False},
        paths.refine_group("sad1"): {"used": True, "shape_used": True},
        paths.refine_group("sad2"): {"used": True, "shape_used": True},
        paths.refine_group("too"): {"used": False, "shape_used": False},
        paths.CONSENSUS: {"used": True, "problem": "", "takes": ["sad1", "x", "y"]},
    }
    datasets = {
        paths.refine("neutral", "valid"): np.ones(3, bool),
        paths.consensus("sad1", "valid"): np.ones(3, bool),
    }
    write_part(store, datasets, attrs=attrs)
    with h5py.File(store) as h5:
        said = {t: correspondence(h5, t) for t in ("neutral", "car", "sad1", "sad2", "too")}
    assert said == {
        "neutral": "",
        "car": "; refined by its texture",
        "sad1": "; refined by its shape (its texture does not correlate with the neutral's), "
        "registered to 2 other such takes by their shared texture",
        "sad2": "; refined by its shape (its texture does not correlate with the neutral's)",
        "too": "; template fit kept (see the warnings)",
    }


def test_a_stale_banner_goes_on_top_of_the_page_and_comes_off_byte_for_byte(tmp_path):
    """A stopped subject's earlier page gets one banner right after ``<body>`` (its note
    escaped; marking again replaces it), and taking it off gives the page back as written,
    line ends and all; no page: nothing to mark."""
    page = tmp_path / "report.html"
    written = (
        "<!DOCTYPE html>\r\n<html><head></head><body><header><h1>s1</h1></header>\n</body></html>\n"
    )
    page.write_bytes(written.encode())
    assert mark_stale(page, "s1 stopped: <neutral> unreadable & more")
    text = page.read_text()
    assert text.startswith("<!DOCTYPE html>\n<html><head></head><body><!-- scan2morph: stale -->")
    assert "s1 stopped: &lt;neutral&gt; unreadable &amp; more</div>" in text
    assert mark_stale(page, "s1 stopped again")
    text = page.read_text()
    assert text.count('role="alert"') == 1 and "stopped again" in text and "&lt;neutral" not in text
    assert clear_stale(page) and page.read_bytes() == written.encode()
    assert not clear_stale(page) and page.read_bytes() == written.encode()
    assert not mark_stale(tmp_path / "none.html", "x") and not clear_stale(tmp_path / "none.html")


def test_the_inputs_and_the_coordinates_say_each_thing_once(tmp_path):
    """The audit of the figures and the report (its findings 15, 16): a thumbnail's caption
    read "neutral: neutral neutral, range, ..." (take id, kind and label alike), and the modal
    coordinates' table "q = Q^T M v" where the default per-vertex basis projects with W."""
    from scan2morph.report.sections import _projection, inputs

    with h5py.File(tmp_path / "s.h5", "w") as h5:
        for take, kind, label in (("neutral", "neutral", "neutral"), ("car", "viseme", "car"),
                                  ("smile1", "expression", "smile")):  # fmt: skip
            h5.create_group(paths.take(take)).attrs.update(
                {"kind": kind, "label": label, "modality": "range"}
            )
            h5[paths.range_image(take, "color")] = np.zeros((48, 64, 3), np.uint8)
        (block,) = inputs(h5, ["neutral", "car", "smile1"], 32)
        assert [t["text"] for t in block["thumbs"]] == [
            "neutral: range, 64x48 px",
            "car: viseme, range, 64x48 px",
            "smile1: expression smile, range, 64x48 px",
        ]
        assert _projection(h5) == "Q^T M v"  # no physics recorded: the paper's Eq. 7
        h5[paths.modal("physics")] = json.dumps({"coordinates": "vertex"})
        assert _projection(h5) == "Q^T W v (W: the mass shared equally by the vertices)"
        del h5[paths.modal("physics")]
        h5[paths.modal("physics")] = json.dumps({"coordinates": "mass"})
        assert _projection(h5) == "Q^T M v"


def test_the_accuracy_summary_gives_units_and_a_column_per_modality():
    """The figures audit's finding 13: the summary was one key / value dump, the by-modality
    part flattened into it ("by_modality range takes" with a JSON list as its value) and the
    units only in the names."""
    summary = {
        "align_rotation_deg_max": 0.085,
        "mesh_rms_mm_max": 0.197,
        "click_noise_px_used": 0.45,
        "by_modality": {
            "range": {"align_rotation_deg_max": 0.085, "takes": ["man", "she"]},
            "stereo": {"align_rotation_deg_max": 0.016, "coverage_min": 0.89, "takes": ["neutral"]},
        },
    }
    first, second = report_accuracy.summary_tables(summary)

    def texts(block):
        return [[c["text"] for c in row] for row in block["table"]["rows"]]

    assert first["table"]["columns"] == ["measure", "unit", "value"]
    assert texts(first) == [
        ["align_rotation_deg_max", "deg", "0.085"],
        ["mesh_rms_mm_max", "mm", "0.197"],
        ["click_noise_px_used", "px", "0.45"],
    ]
    assert second["table"]["columns"] == ["measure", "unit", "range", "stereo"]
    assert texts(second) == [
        ["align_rotation_deg_max", "deg", "0.085", "0.016"],
        ["coverage_min", "fraction", "n/a", "0.89"],
        ["takes", "", "man, she", "neutral"],
    ]
