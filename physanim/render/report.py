"""A self-contained HTML report per run (``index.html``): video, images/plots, key figures,
variant comparison, and per stage its runtime, parameters and provenance.

Opens from disk with no server: links to the video and images are relative to the report's
folder, CSS is inline, there are no scripts and no external assets.
"""

from __future__ import annotations

import html
import json
import os
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,Helvetica,Arial,sans-serif;
margin:0;background:#f5f6f8;color:#1f2328;line-height:1.45}
main{max-width:1200px;margin:0 auto;padding:24px 32px 48px}
header{background:#1f3a5f;color:#fff;padding:20px 32px}
header h1{margin:0;font-size:1.6em} header p{margin:4px 0 0;opacity:.8;font-size:.9em}
h2{font-size:1.2em;margin:32px 0 12px;padding-bottom:4px;border-bottom:2px solid #d0d7de}
section.card{background:#fff;border:1px solid #d0d7de;border-radius:8px;padding:16px 20px;
margin-bottom:16px}
section.warnings{background:#fff1f0;border-color:#cf222e;margin-top:24px}
section.warnings h2{color:#cf222e;margin-top:0;border-bottom-color:#f5c2c0}
video{width:100%;border-radius:6px;background:#000}
.grid{display:grid;grid-template-columns:repeat(auto-fit,minmax(460px,1fr));gap:16px}
figure{margin:0;background:#fff;border:1px solid #d0d7de;border-radius:8px;padding:10px}
figure img,figure video{width:100%;height:auto;display:block}
section.card figure{margin-bottom:10px}
figcaption{font-size:.9em;color:#57606a;margin-top:6px}
table{border-collapse:collapse;width:100%;font-size:.92em}
th,td{padding:6px 10px;border-bottom:1px solid #e5e8eb;text-align:left;vertical-align:top}
th{background:#f0f3f6;font-weight:600} td.num{text-align:right;font-variant-numeric:tabular-nums}
tr:hover td{background:#fafbfc}
details{border:1px solid #d0d7de;border-radius:6px;margin:8px 0;background:#fff}
summary{cursor:pointer;padding:8px 12px;font-weight:600}
summary span{font-weight:400;color:#57606a;margin-left:8px}
details .body{padding:4px 16px 12px}
pre{background:#f6f8fa;border-radius:6px;padding:10px;overflow-x:auto;font-size:.85em;margin:6px 0}
.tag{display:inline-block;border-radius:10px;padding:0 8px;font-size:.8em;font-weight:600}
.tag.ran{background:#dafbe1;color:#116329}.tag.cached{background:#ddf4ff;color:#0969da}
.tag.other{background:#eee;color:#444}
code{font-size:.9em}
"""


class ReportError(FileNotFoundError):
    """A file the report links to does not exist."""


def _e(value: Any) -> str:
    return html.escape(str(value))


def _fmt(value: Any) -> str:
    """Numbers to 4 significant digits, everything else as text."""
    if isinstance(value, bool) or value is None:
        return str(value)
    if isinstance(value, int):
        return f"{value:d}"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _rel(path: str | Path, out_dir: Path, what: str) -> str:
    """Link to ``path`` from ``out_dir``; a relative path is relative to the working
    directory, like every other path (never to ``out_dir``)."""
    full = Path(path).resolve()
    if not full.is_file():
        raise ReportError(f"report: {what} {path} does not exist; write it before build_report")
    return Path(os.path.relpath(full, out_dir.resolve())).as_posix()


def _pre(data: Any) -> str:
    return f"<pre>{_e(json.dumps(data, indent=2, sort_keys=True, default=str))}</pre>"


def _table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    head = "".join(f"<th>{_e(h)}</th>" for h in header)
    body = "".join(
        "<tr>"
        + "".join(
            f'<td class="num">{_e(_fmt(c))}</td>'
            if isinstance(c, int | float) and not isinstance(c, bool)
            else f"<td>{_e(c)}</td>"
            for c in row
        )
        + "</tr>"
        for row in rows
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _stages(stage_table: Sequence[Mapping[str, Any]]) -> str:
    rows = []
    total = 0.0
    for s in stage_table:
        if "stage" not in s:
            raise ValueError(f"stage_table entry without a 'stage' name: {sorted(s)}")
        seconds = s.get("seconds")
        total += float(seconds or 0.0)
        rows.append((s["stage"], s.get("key", ""), s.get("action", ""), seconds))
    summary = _table(("stage", "key", "action", "seconds"), rows)
    summary += f"<p>Total: <b>{total:.2f} s</b> over {len(stage_table)} stages.</p>"
    blocks = []
    for s in stage_table:
        action = str(s.get("action", ""))
        cls = action if action in ("ran", "cached") else "other"
        seconds = s.get("seconds")
        time = f"{float(seconds):.2f} s" if seconds is not None else ""
        extra = {
            k: v for k, v in s.items() if k not in ("stage", "key", "action", "seconds", "params")
        }
        body = f"<h4>Parameters</h4>{_pre(s.get('params', {}))}"
        for name, value in extra.items():
            body += f"<h4>{_e(name.capitalize())}</h4>{_pre(value)}"
        blocks.append(
            f"<details><summary>{_e(s['stage'])} <span class='tag {cls}'>{_e(action)}</span>"
            f"<span>{_e(time)} &middot; key <code>{_e(s.get('key', ''))}</code></span>"
            f"</summary><div class='body'>{body}</div></details>"
        )
    return summary + "".join(blocks)


def _variants(variants: Mapping[str, Mapping[str, Any]]) -> str:
    names = list(variants)
    measures = list(dict.fromkeys(m for v in variants.values() for m in v))
    rows = [[m, *(variants[n].get(m, "") for n in names)] for m in measures]
    return _table(("measure", *names), rows)


def _video(src: str) -> str:
    return f"<video controls loop muted playsinline preload='metadata' src='{src}'></video>"


def _media(files: Sequence[tuple[str, str | Path]], out_dir: Path) -> str:
    """Videos and images (caption, path) as HTML, links relative to ``out_dir``."""
    parts = []
    for caption, path in files:
        src = _e(_rel(path, out_dir, f"file {caption!r}"))
        if Path(path).suffix.lower() in (".mp4", ".webm"):
            tag = _video(src)
        else:
            tag = f"<a href='{src}'><img src='{src}' alt='{_e(caption)}' loading='lazy'></a>"
        parts.append(f"<figure>{tag}<figcaption>{_e(caption)}</figcaption></figure>")
    return "".join(parts)


def build_report(
    out_dir: str | Path,
    *,
    title: str,
    video: str | Path | None = None,
    images: Sequence[tuple[str, str | Path]] = (),
    key_figures: Mapping[str, Any] | None = None,
    stage_table: Sequence[Mapping[str, Any]] = (),
    variants: Mapping[str, Mapping[str, Any]] | None = None,
    galleries: Mapping[str, Sequence[tuple[str, str | Path]]] | None = None,
    tables: Mapping[str, tuple[Sequence[str], Sequence[Sequence[Any]]]] | None = None,
    warnings: Sequence[str] = (),
    subtitle: str = "",
    viewer: str | Path | None = None,
) -> Path:
    """Write ``out_dir/index.html`` and return its path.

    ``video``/``images`` (caption, path): files that must exist (absolute or relative to the
    working directory; linked relatively).  ``key_figures``: name -> value (numbers to 4
    significant digits; put the unit in the name).  ``stage_table``: one dict per stage
    with ``stage`` and optionally ``key``, ``action`` ("ran"/"cached"), ``seconds``,
    ``params`` (dict) and any further entries (e.g. ``provenance``) shown as JSON in a
    collapsible block.  ``variants``: variant -> measure -> value, shown as one column per
    variant.  ``galleries``: variant -> (caption, file) videos (.mp4/.webm) and images, one
    card per variant side by side. ``warnings``: lines shown first, in a red box.
    ``viewer``: a page (``physanim.render.viewer``) embedded after the video, or a line of
    text saying why there is none.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    stamp = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        "<meta name='viewport' content='width=device-width, initial-scale=1'>",
        f"<title>{_e(title)}</title><style>{_CSS}</style></head><body>",
        f"<header><h1>{_e(title)}</h1><p>{_e(subtitle)} generated {stamp}</p></header><main>",
    ]
    if warnings:
        items = "".join(f"<li>{_e(w)}</li>" for w in warnings)
        parts.append(
            f"<section class='card warnings'><h2>Warnings ({len(warnings)})</h2>"
            f"<ul>{items}</ul></section>"
        )
    if video is not None:
        src = _e(_rel(video, out_dir, "video"))
        parts.append(
            "<h2>Video</h2><section class='card'>"
            f"{_video(src)}"
            f"<p><a href='{src}'>{src}</a></p></section>"
        )
    if isinstance(viewer, Path):
        src = _e(_rel(viewer, out_dir, "viewer"))
        parts.append(
            "<h2>3D viewer</h2><section class='card'>"
            f"<iframe src='{src}' title='3D viewer' style='width:100%;height:520px;border:0'>"
            f"</iframe><p><a href='{src}'>open it alone</a>: drag to orbit, wheel to zoom, "
            "the slider to scrub, the menu to switch between the FEM and the capture</p>"
            "</section>"
        )
    elif viewer:
        parts.append(f"<h2>3D viewer</h2><section class='card'><p>{_e(viewer)}</p></section>")
    if key_figures:
        table = _table(("figure", "value"), list(key_figures.items()))
        parts.append(f"<h2>Key figures</h2><section class='card'>{table}</section>")
    for heading, (header, rows) in (tables or {}).items():
        card = _table(header, rows)
        parts.append(f"<h2>{_e(heading)}</h2><section class='card'>{card}</section>")
    if variants:
        parts.append(f"<h2>Variants</h2><section class='card'>{_variants(variants)}</section>")
    if galleries:
        cards = "".join(
            f"<section class='card'><h3>{_e(name)}</h3>{_media(files, out_dir)}</section>"
            for name, files in galleries.items()
        )
        parts.append(f"<h2>Per variant</h2><div class='grid'>{cards}</div>")
    if images:
        figs = "".join(
            f"<figure><a href='{_e(r)}'><img src='{_e(r)}' alt='{_e(c)}' loading='lazy'></a>"
            f"<figcaption>{_e(c)}</figcaption></figure>"
            for c, r in ((c, _rel(p, out_dir, f"image {c!r}")) for c, p in images)
        )
        parts.append(f"<h2>Figures</h2><div class='grid'>{figs}</div>")
    if stage_table:
        parts.append(f"<h2>Stages</h2><section class='card'>{_stages(stage_table)}</section>")
    parts.append("</main></body></html>")
    path = out_dir / "index.html"
    partial = out_dir / f".index.html.{os.getpid()}"  # renamed into place: never half-written
    partial.write_text("\n".join(parts), encoding="utf-8")
    partial.replace(path)
    return path
