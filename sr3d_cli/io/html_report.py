"""One self-contained HTML page for a batch: metrics (sortable, worst frames first), per-frame
pictures, time per stage and failures with their reasons.

Read from what the commands wrote: ``metrics.json`` (evaluate), ``log/<frame>.json`` (every
per-frame command: status, seconds, stage seconds, error), ``repaired/<frame>_preview.png``,
``grasps/<frame>_preview.png`` and ``eval_plots/<pred>/<frame>.png``. Pictures are embedded as
JPEG data URIs, so the page is one file that opens anywhere.
"""

from __future__ import annotations

import base64
import html
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sr3d_cli.io.scene import SceneSource

COLUMNS = (("rmse", "RMSE (m)", "{:.4f}"), ("rel", "REL", "{:.4f}"), ("mae", "MAE (m)", "{:.4f}"),
           ("delta_1.05", "d<1.05 (%)", "{:.1f}"), ("coverage", "valid (%)", "{:.1f}"))
PICTURES = (("repaired", "_preview.png", "raw and repaired depth"),
            ("grasps", "_preview.png", "grasps"))


@dataclass
class FrameEntry:
    """What the page shows of one frame."""

    key: str
    metrics: dict[str, dict] = field(default_factory=dict)  # {pred: metrics}
    commands: dict[str, dict] = field(default_factory=dict)  # log/<frame>.json "commands"
    pictures: list[tuple[str, Path]] = field(default_factory=list)  # (caption, file)


@dataclass
class BatchReport:
    frames: list[FrameEntry]
    preds: list[str]
    means: dict[str, dict]
    protocol: dict | None
    failures: list[tuple[str, str, str]]  # (frame or file, command, reason)


def _read_json(path: Path) -> dict | None:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def gather(groups: list[tuple[str, list[SceneSource], Path]]) -> BatchReport:
    """Collect a batch from ``(label, scene sources, folder holding metrics.json)`` per SCENE
    argument; ``label`` prefixes the frame keys when several are given ("" for none)."""
    frames: list[FrameEntry] = []
    preds: list[str] = []
    means: dict[str, dict] = {}
    protocol = None
    failures: list[tuple[str, str, str]] = []
    for label, sources, metrics_root in groups:
        doc = _read_json(metrics_root / "metrics.json") or {}
        per_frame = doc.get("frames", {})
        named = doc.get("predictions", [])
        order = [p for p in named if p in doc.get("means", {})]
        order += [p for p in doc.get("means", {}) if p not in order]
        for pred in order:
            name = f"{label}: {pred}" if label else pred
            means[name] = doc["means"][pred]
            if pred not in preds:
                preds.append(pred)
        protocol = protocol or doc.get("protocol")
        failures += [(line.split(":", 1)[0], "evaluate", line) for line in doc.get("failed", [])]
        for source in sources:
            try:
                ids = source.frame_ids()
            except OSError:
                continue
            for fid in ids:
                key = source.frame_key(fid)
                entry = FrameEntry(f"{label}/{key}" if label else key,
                                   metrics=per_frame.get(key, {}))
                log = _read_json(source.output_path("log", fid, ".json")) or {}
                entry.commands = log.get("commands", {})
                for command, run in entry.commands.items():
                    if run.get("status") == "failed":
                        failures.append((entry.key, command, run.get("error", "")))
                for stage, suffix, caption in PICTURES:
                    path = source.output_path(stage, fid, suffix)
                    if path.is_file():
                        entry.pictures.append((caption, path))
                plots = source.out / "eval_plots"
                if plots.is_dir():
                    for folder in sorted(p for p in plots.iterdir() if p.is_dir()):
                        path = folder / f"{fid}.png"
                        if path.is_file():
                            entry.pictures.append((f"error map: {folder.name}", path))
                frames.append(entry)
    if "repaired" in preds:  # the tool's own output leads the table and the ranking
        preds.insert(0, preds.pop(preds.index("repaired")))
    frames.sort(key=lambda f: _badness(f, preds[0] if preds else None), reverse=True)
    return BatchReport(frames, preds, means, protocol, failures)


def _value(metrics: dict, key: str) -> float:
    v = metrics.get(key)
    return math.nan if v is None else float(v)


def _badness(entry: FrameEntry, pred: str | None) -> tuple:
    """Sort key, worst first: failed frames, then the first prediction's RMSE (frames without
    metrics last)."""
    failed = any(r.get("status") == "failed" for r in entry.commands.values())
    rmse = _value(entry.metrics.get(pred, {}), "rmse") if pred else math.nan
    return (failed, not math.isnan(rmse), -math.inf if math.isnan(rmse) else rmse)


def stage_times(frames: list[FrameEntry]) -> list[tuple[str, int, float, float, float]]:
    """(command or command/stage, frames, mean s, median s, max s) over the frames' logs."""
    samples: dict[str, list[float]] = {}
    for entry in frames:
        for command, run in entry.commands.items():
            samples.setdefault(command, []).append(float(run.get("seconds", 0.0)))
            for stage, s in run.get("stages", {}).items():
                samples.setdefault(f"{command} / {stage}", []).append(float(s))
    return [(name, len(v), float(np.mean(v)), float(np.median(v)), float(np.max(v)))
            for name, v in sorted(samples.items())]


def picture_uri(path: Path, max_width: int = 1200) -> str:
    """A picture as a JPEG data URI, shrunk to at most ``max_width`` pixels wide."""
    import cv2

    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        return ""
    if image.shape[1] > max_width:
        h = round(image.shape[0] * max_width / image.shape[1])
        image = cv2.resize(image, (max_width, h), interpolation=cv2.INTER_AREA)
    ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 85])
    return "data:image/jpeg;base64," + base64.b64encode(data.tobytes()).decode("ascii") if ok \
        else ""


def _cell(value: float, fmt: str, percent: bool = False) -> str:
    if math.isnan(value):
        return '<td data-value="">-</td>'
    shown = fmt.format(100 * value if percent else value)
    return f'<td data-value="{value:.9g}">{shown}</td>'


STYLE = """
body{font-family:system-ui,sans-serif;margin:1.5em;color:#111}
table{border-collapse:collapse;margin:.5em 0 1.5em}
th,td{border:1px solid #bbb;padding:.25em .6em;text-align:right}
th{background:#eee;cursor:pointer;user-select:none}
#frames td:nth-child(2),#frames th:nth-child(2){text-align:left}
#means td:first-child,#times td:first-child{text-align:left}
tr.failed td{background:#fde2e2}
img{max-width:100%;display:block;margin:.3em 0 1em}
details{border-top:1px solid #ccc;padding:.4em 0}
.note{color:#555}
"""

SCRIPT = """
function sortTable(table, col, descending) {
  const body = table.tBodies[0];
  const rows = Array.from(body.rows);
  const key = r => r.cells[col].dataset.value;
  rows.sort((a, b) => {
    const x = key(a), y = key(b);
    if (x === '' && y === '') return 0;
    if (x === '') return 1;
    if (y === '') return -1;
    const nx = parseFloat(x), ny = parseFloat(y);
    const c = (isNaN(nx) || isNaN(ny)) ? x.localeCompare(y) : nx - ny;
    return descending ? -c : c;
  });
  rows.forEach(r => body.appendChild(r));
  table.dataset.sortedBy = col + (descending ? ' desc' : ' asc');
}
document.querySelectorAll('table.sortable').forEach(table => {
  Array.from(table.tHead.rows[0].cells).forEach((th, col) => {
    th.title = 'sort';
    th.addEventListener('click', () => {
      const was = table.dataset.sortedBy === col + ' desc';
      sortTable(table, col, !was);
    });
  });
  const d = table.dataset.defaultSort;
  if (d !== undefined && d !== '')
    sortTable(table, parseInt(d), table.dataset.defaultOrder === 'desc');
});
document.body.dataset.ready = '1';
"""


def render(report: BatchReport, title: str = "sr3d report") -> str:
    """The page, as one HTML string (no external files)."""
    e = html.escape
    pred0 = report.preds[0] if report.preds else None
    parts = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{e(title)}"
             f"</title><style>{STYLE}</style></head><body><h1>{e(title)}</h1>"]
    failed = sum(1 for f in report.frames
                 if any(r.get("status") == "failed" for r in f.commands.values()))
    parts.append(f"<p>{len(report.frames)} frames, {failed} with a failed command, "
                 f"{len(report.failures)} failures in all.</p>")
    if report.protocol:
        p = report.protocol
        sets = "; ".join(f"{k}: {v}" for k, v in p.get("pixel_sets", {}).items())
        parts.append(f"<p class='note'>Metrics: protocol {e(str(p.get('name')))}, resolution "
                     f"{e(str(p.get('resolution')))}; {e(sets)}; {e(str(p.get('holes', '')))}"
                     "</p>")
    if report.means:
        parts.append("<h2>Means</h2><table id='means'><thead><tr><th>prediction</th><th>frames"
                     "</th>" + "".join(f"<th>{e(h)}</th>" for _, h, _ in COLUMNS)
                     + "</tr></thead><tbody>")
        for name, m in report.means.items():
            parts.append(f"<tr><td>{e(name)}</td><td>{int(m.get('frames', 0))}</td>"
                         + "".join(_cell(_value(m, k), f, k == "coverage") for k, _, f in COLUMNS)
                         + "</tr>")
        parts.append("</tbody></table>")
    parts.append(_frames_table(report, pred0))
    times = stage_times(report.frames)
    if times:
        parts.append("<h2>Time per stage</h2><table id='times' class='sortable'><thead><tr>"
                     "<th>command / stage</th><th>frames</th><th>mean (s)</th><th>median (s)"
                     "</th><th>max (s)</th></tr></thead><tbody>")
        for name, n, mean, median, top in times:
            parts.append(f"<tr><td data-value='{e(name)}'>{e(name)}</td><td data-value='{n}'>{n}"
                         "</td>" + "".join(_cell(v, "{:.3f}") for v in (mean, median, top))
                         + "</tr>")
        parts.append("</tbody></table>")
    parts.append("<h2>Failures</h2>")
    if report.failures:
        parts.append("<ul id='failures'>" + "".join(
            f"<li><b>{e(where)}</b> ({e(command)}): {e(reason)}</li>"
            for where, command, reason in report.failures) + "</ul>")
    else:
        parts.append("<p id='failures'>none</p>")
    parts.append("<h2>Frames</h2>")
    for entry in report.frames:
        parts.append(_frame_section(entry, pred0))
    parts.append(f"<script>{SCRIPT}</script></body></html>")
    return "\n".join(parts)


def _frames_table(report: BatchReport, pred0: str | None) -> str:
    e = html.escape
    head = ["<th>rank</th>", "<th>frame</th>"]
    for pred in report.preds:
        head += [f"<th>{e(pred)} {e(h)}</th>" for _, h, _ in COLUMNS]
    head += ["<th>time (s)</th>", "<th>status</th>"]
    rows = [f"<h2>Metrics per frame</h2><p class='note'>Ranked worst first (failed frames, then "
            f"by {e(pred0 or 'nothing')} RMSE); click a heading to sort.</p>"
            "<table id='frames' class='sortable' data-default-sort='0' "
            "data-default-order='asc'><thead><tr>" + "".join(head) + "</tr></thead><tbody>"]
    for rank, entry in enumerate(report.frames, 1):
        failed = [c for c, r in entry.commands.items() if r.get("status") == "failed"]
        seconds = sum(float(r.get("seconds", 0.0)) for r in entry.commands.values())
        anchor = "f-" + "".join(c if c.isalnum() else "-" for c in entry.key)
        cells = [f"<td data-value='{rank}'>{rank}</td>",
                 f"<td data-value='{e(entry.key)}'><a href='#{anchor}'>{e(entry.key)}</a></td>"]
        for pred in report.preds:
            m = entry.metrics.get(pred, {})
            cells += [_cell(_value(m, k), f, k == "coverage") for k, _, f in COLUMNS]
        cells.append(_cell(seconds if entry.commands else math.nan, "{:.2f}"))
        status = ("failed: " + ", ".join(failed)) if failed else ("done" if entry.commands
                                                                  else "-")
        cells.append(f"<td data-value='{e(status)}'>{e(status)}</td>")
        rows.append(f"<tr class='{'failed' if failed else ''}'>" + "".join(cells) + "</tr>")
    rows.append("</tbody></table>")
    return "\n".join(rows)


def _frame_section(entry: FrameEntry, pred0: str | None) -> str:
    e = html.escape
    anchor = "f-" + "".join(c if c.isalnum() else "-" for c in entry.key)
    summary = e(entry.key)
    m = entry.metrics.get(pred0, {}) if pred0 else {}
    if m:
        summary += f" &mdash; {e(pred0)} RMSE {_value(m, 'rmse'):.4f} m"
    out = [f"<details id='{anchor}' open><summary>{summary}</summary>"]
    for command, run in entry.commands.items():
        stages = ", ".join(f"{k} {v:.2f} s" for k, v in run.get("stages", {}).items())
        line = f"{e(command)}: {e(run.get('status', ''))}, {float(run.get('seconds', 0)):.2f} s"
        line += f" ({e(stages)})" if stages else ""
        line += f" &mdash; {e(run['error'])}" if run.get("error") else ""
        out.append(f"<div class='note'>{line}</div>")
    for caption, path in entry.pictures:
        uri = picture_uri(path)
        if uri:
            out.append(f"<figure><figcaption>{e(caption)}</figcaption>"
                       f"<img alt='{e(caption)} of {e(entry.key)}' src='{uri}'></figure>")
    out.append("</details>")
    return "\n".join(out)
