"""``sr3d report``: one self-contained HTML page for a batch, parsed here, and opened in a real
headless browser where Chromium is installed."""

from __future__ import annotations

import base64
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from sr3d_cli.cli import cli
from sr3d_cli.io import preview
from sr3d_cli.io.images import read_depth, write_depth
from sr3d_cli.io.atomic import write_png
from tests.conftest import make_native_scene


def _run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def batch(tmp_path_factory) -> Path:
    """Four frames: repaired depth exact (000000), 5 cm off on the object (000001), the raw
    depth with its holes (000002); 000003's depth file is broken, so every command fails it.
    segment writes the run logs; evaluate --plot the metrics and error maps."""
    root = make_native_scene(tmp_path_factory.mktemp("rep") / "scene", 4)
    for k in range(3):
        fid = f"{k:06d}"
        gt = read_depth(root / "gt" / "depth" / f"{fid}.png", 0.001)
        raw = read_depth(root / "depth" / f"{fid}.png", 0.001)
        repaired = [gt, np.where(gt < 0.5, gt + 0.05, gt), raw][k]
        write_depth(root / "repaired" / f"{fid}.png", repaired, 0.001)
        ids = np.zeros(gt.shape, np.int32)
        ids[8:14, 10:18] = 1
        rgb = np.full(gt.shape + (3,), 120, np.uint8)
        write_png(root / "repaired" / f"{fid}_preview.png",
                  preview.preview_image(rgb, raw, repaired, ids))
    (root / "depth" / "000003.png").write_bytes(b"not a png")
    assert _run("segment", root, "-q").exit_code == 1
    assert _run("evaluate", root, "--pred", "repaired", "--pred", "depth", "--plot",
                "-q").exit_code == 1
    return root


class _Page(HTMLParser):
    """Rows of the tables (cell texts), the images' sources and the failures list items."""

    def __init__(self):
        super().__init__()
        self.tables: dict[str, list[list[str]]] = {}
        self.images: list[str] = []
        self.links: list[str] = []
        self.failures: list[str] = []
        self._table = self._row = self._cell = None
        self._in_failures = self._item = False

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "table":
            self._table = self.tables.setdefault(a.get("id", ""), [])
        elif tag == "tr" and self._table is not None:
            self._row = []
            self._table.append(self._row)
        elif tag in ("td", "th") and self._row is not None:
            self._cell = ""
        elif tag == "img":
            self.images.append(a["src"])
        elif tag in ("a", "link", "script") and (a.get("href") or a.get("src")):
            self.links.append(a.get("href") or a.get("src"))
        elif tag == "ul" and a.get("id") == "failures":
            self._in_failures = True
        elif tag == "li" and self._in_failures:
            self.failures.append("")
            self._item = True

    def handle_endtag(self, tag):
        if tag == "table":
            self._table = None
        elif tag in ("td", "th") and self._cell is not None:
            self._row.append(self._cell.strip())
            self._cell = None
        elif tag == "ul":
            self._in_failures = False
        elif tag == "li":
            self._item = False

    def handle_data(self, data):
        if self._cell is not None:
            self._cell += data
        if self._item:
            self.failures[-1] += data


def _page(path: Path) -> _Page:
    page = _Page()
    page.feed(path.read_text(encoding="utf-8"))
    return page


def test_report_ranks_frames_worst_first_with_pictures_times_and_failures(batch, tmp_path):
    out = tmp_path / "report.html"
    result = _run("report", batch, "-o", out)
    assert result.exit_code == 0, result.output
    assert "4 frames" in result.output
    page = _page(out)
    header, *rows = page.tables["frames"]
    assert header[:3] == ["rank", "frame", "repaired RMSE (m)"]
    assert [r[1] for r in rows] == ["000003", "000002", "000001", "000000"]
    assert rows[0][-1] == "failed: segment"
    rmse = [float(r[2]) for r in rows[1:]]
    assert rmse[1] == pytest.approx(0.05, abs=1e-3) and rmse[2] == 0.0 and rmse[0] > 0.2
    # one picture per frame and kind: previews and both error maps, embedded as JPEG
    assert len(page.images) == 3 * 3
    for src in page.images:
        assert src.startswith("data:image/jpeg;base64,")
        image = cv2.imdecode(np.frombuffer(base64.b64decode(src.split(",", 1)[1]), np.uint8),
                             cv2.IMREAD_COLOR)
        assert image is not None and image.shape[1] in (32, 96)
    assert all(link.startswith("#") for link in page.links)  # nothing outside the file
    times = {r[0]: r for r in page.tables["times"][1:]}
    assert times["segment"][1] == "4"
    assert any("000003" in f and "segment" in f and "depth/000003.png" in f
               for f in page.failures)
    assert any("evaluate" in f and "000003" in f for f in page.failures)
    means = {r[0]: r for r in page.tables["means"][1:]}
    assert set(means) == {"repaired", "depth"} and means["repaired"][1] == "3"


def test_report_over_two_scenes_labels_their_frames(batch, tmp_path):
    other = make_native_scene(tmp_path / "other", 1)
    out = tmp_path / "two.html"
    result = _run("report", batch, other, "-o", out)
    assert result.exit_code == 0, result.output
    keys = {r[1] for r in _page(out).tables["frames"][1:]}
    assert keys == {f"scene/{k:06d}" for k in range(4)} | {"other/000000"}


def _browser() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable",
                 "chrome", "headless_shell"):
        if shutil.which(name):
            return shutil.which(name)
    return None


def test_report_in_a_headless_browser(batch, tmp_path):
    browser = _browser()
    if browser is None:
        pytest.skip("no Chromium or Chrome on PATH: the page's script is not run in a browser "
                    "here (the page is parsed by the other tests)")
    out = tmp_path / "report.html"
    assert _run("report", batch, "-o", out).exit_code == 0
    # the page's own script re-sorts on load; make it sort by repaired RMSE, best first
    text = out.read_text(encoding="utf-8").replace(
        "data-default-sort='0' data-default-order='asc'",
        "data-default-sort='2' data-default-order='asc'")
    out.write_text(text, encoding="utf-8")
    dom = subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu",
                          "--dump-dom", out.as_uri()], capture_output=True, text=True,
                         timeout=120).stdout
    assert 'data-ready="1"' in dom  # the script ran to its end
    assert 'data-sorted-by="2 asc"' in dom
    dumped = tmp_path / "dom.html"
    dumped.write_text(dom, encoding="utf-8")
    rows = _page(dumped).tables["frames"][1:]
    assert [r[1] for r in rows] == ["000000", "000001", "000002", "000003"]  # no value: last
    assert re.search(r"<img[^>]+src=\"data:image/jpeg", dom)
