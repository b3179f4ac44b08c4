"""The run report a person looks at: ``OUT/report.html`` (``loom report OUT``; ``loom render`` writes it last).

One self-contained HTML file that opens from disk: every picture (matplotlib PNGs, the AQM maps
the coordinator wrote beside the segment records, a filmstrip of the frames) and the preview
video are embedded as data URIs, the page needs no script and no network. It shows, from
``report.json`` and the segment records (pipeline/segments/records.py):

* the segments: the paper's Table 1 (K_i, N_frame, F_max) with d_AQM and p_me, and plots of
  N_frame, F_max and d_AQM per segment; Fig. 6 and the F_max steps (pipeline/report/segment_plot.py);
* Table 2, the cost of a frame by stage (pipeline/report/tables.stage_table), per segment and in all,
  and the compositing time, photons and mean collection window of every frame;
* Fig. 5, the distribution of collection-window lengths over the elements at each K, and Fig. 3d,
  the AQM map of I1(K) against I2(K) at each K (its last N_frame step);
* a filmstrip, the preview video, what was skipped and why (pipeline/report/skipped.py), the settings.

A video larger than ``VIDEO_EMBED_MAX`` bytes is linked (relative path) instead of embedded, so the
page stays loadable; the report says so.
"""
from __future__ import annotations

import base64
import html
import io
import json
import os
import time
from pathlib import Path
from string import Template

from pipeline.errors import LoomError
from pipeline.frames.images import frame_paths
from pipeline.segments.records import CAPPED_NOTE, SegmentRecord, read_records, record_path, used_fmax_step

from .figures import figure, png_bytes
from .segment_plot import plot_segments
from .skipped import summary_lines
from .tables import ROWS, stage_table, store_size_line

VIDEO_EMBED_MAX = 64 * 2**20
FILMSTRIP_FRAMES = 12
THUMB_WIDTH = 240

PAGE = Template("""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<link rel="icon" href="data:,">
<title>photonloom report: $title</title>
<style>
body { font: 14px/1.45 system-ui, sans-serif; margin: 1.5em auto; max-width: 1180px; color: #222; padding: 0 1em; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; } h2 { margin-top: 1.6em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; margin: 0.5em 0; font-variant-numeric: tabular-nums; }
th, td { border: 1px solid #ccc; padding: 3px 8px; text-align: right; } th { background: #eef; }
td.l, th.l { text-align: left; } .muted { color: #666; } figure { margin: 0.6em 0; display: inline-block; }
figcaption { font-size: 12px; color: #555; } img.plot { max-width: 100%; }
.strip { display: flex; flex-wrap: wrap; gap: 6px; } .strip figure { margin: 0; }
.maps { display: flex; flex-wrap: wrap; gap: 10px; } ul.skip { margin: 0.3em 0; }
</style></head>
<body>
<h1>photonloom report: $title</h1>
<p class="muted">$subtitle</p>
<section id="summary"><h2>Summary</h2>$summary</section>
<section id="segments"><h2>Segments (Table 1, §5.2)</h2>$segments</section>
<section id="costs"><h2>Cost of a frame (Table 2, §6)</h2>$costs</section>
<section id="windows"><h2>Collection windows at K (Fig. 5)</h2>$windows</section>
<section id="aqm"><h2>AQM maps at K (Fig. 3d)</h2>$aqm</section>
<section id="frames"><h2>Frames</h2>$filmstrip</section>
<section id="video"><h2>Preview video</h2>$video</section>
<section id="skipped"><h2>What was skipped, and why</h2>$skipped</section>
<section id="settings"><h2>Settings</h2>$settings</section>
</body></html>
""")


def write_report(out_dir: str | Path, parts: dict[str, str] | None = None) -> Path:
    """Write ``OUT/report.html`` atomically from the render's files; returns its path. ``parts``:
    :func:`page_parts` made beforehand (``loom render`` makes them while the video encodes)."""
    out = Path(out_dir)
    path = out / "report.json"
    if not path.is_file():
        raise LoomError("has no report.json (render it with loom render first)", path=str(out))
    try:
        report = json.loads(path.read_text())
    except ValueError as err:
        raise LoomError(f"not a render report ({err})", path=str(path)) from None
    records = read_records(out)
    page = render_page(out, report, records, parts)
    target = out / "report.html"
    tmp = out / f".report.html.{os.getpid()}.partial"
    tmp.write_text(page, encoding="utf-8")
    os.replace(tmp, target)
    return target


def page_parts(out: Path, report: dict, records: list[SegmentRecord]) -> dict[str, str]:
    """The page's tables and figures (matplotlib, maps, filmstrip): everything but the summary,
    the video, what was skipped and the settings, so none of it waits for the video or the run's
    final times."""
    config = report.get("settings", {}).get("config", {})
    return dict(segments=_segments(out, records, config), costs=_costs(report, records), windows=_windows(records),
                aqm=_aqm_maps(out, records), filmstrip=_filmstrip(out, report.get("frames", [])))


def render_page(out: Path, report: dict, records: list[SegmentRecord], parts: dict[str, str] | None = None) -> str:
    """The HTML text of the report (no I/O beyond reading the render's pictures and video)."""
    title = html.escape(Path(report.get("scene", "?")).name)
    subtitle = html.escape(f"{out.resolve()} · written {time.strftime('%Y-%m-%d %H:%M:%S')}")
    parts = page_parts(out, report, records) if parts is None else parts
    return PAGE.substitute(title=title, subtitle=subtitle, summary=_summary(report, records),
                           video=_video(out, report), skipped=_skipped(report), settings=_settings(report), **parts)


# --- pieces ---------------------------------------------------------------------------------
def _e(value) -> str:
    return html.escape(str(value))


def _table(head: list[str] | None, rows: list[list], left: int = 0, cls: str = "") -> str:
    """An HTML table (``head`` None: no header row); the first ``left`` columns left-aligned."""
    def cell(tag, i, v):
        align = ' class="l"' if i < left else ""
        return f"<{tag}{align}>{_e(v)}</{tag}>"
    header = "" if head is None else "<tr>" + "".join(cell("th", i, h) for i, h in enumerate(head)) + "</tr>"
    return (f"<table class=\"{cls}\">" + header
            + "".join("<tr>" + "".join(cell("td", i, v) for i, v in enumerate(r)) + "</tr>" for r in rows)
            + "</table>")


def _png_uri(data: bytes, mime: str = "image/png") -> str:
    return f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}"


def _figure_uri(fig) -> str:
    return _png_uri(png_bytes(fig, dpi=90))


def _img(uri: str, alt: str, caption: str = "", cls: str = "plot", width: int | None = None) -> str:
    w = f" width=\"{width}\"" if width else ""
    cap = f"<figcaption>{_e(caption)}</figcaption>" if caption else ""
    return f"<figure><img class=\"{cls}\" id=\"{_e(alt)}\" alt=\"{_e(alt)}\" src=\"{uri}\"{w}>{cap}</figure>"


def _summary(report: dict, records: list[SegmentRecord]) -> str:
    t = report.get("times_s", {})
    res = report.get("resolution", ["?", "?"])
    rows = [["scene", report.get("scene", "?")], ["camera", report.get("camera", "?")],
            ["frames", f"{len(report.get('frames', []))} ({_ranges(report.get('frames', []))})"],
            ["written by this run", len(report.get("rendered", []))],
            ["resolution, spp", f"{res[0]}x{res[1]}, {report.get('spp', '?')}"],
            ["photons", report.get("photons", "?")], ["segments", len(records)],
            ["photon batches traced", report.get("photon_batches_traced", "?")],
            ["wall time", (f"{t.get('total_s', 0.0):.1f} s (photons {t.get('shoot_s', 0.0):.1f}, "
                           f"AQM {t.get('aqm_s', 0.0):.1f}, temporal {t.get('temporal_s', 0.0):.1f}, "
                           f"composite {t.get('composite_s', 0.0):.1f}, video {t.get('video_s', 0.0):.1f})")],
            ["rays", ", ".join(f"{k} {v:,}" for k, v in report.get("rays", {}).items())]]
    animations = report.get("animations", {})
    if animations.get("played") or animations.get("left_out"):
        left_out = animations.get("left_out", [])
        rows.insert(2, ["animations", (", ".join(animations.get("played", [])) or "none")
                        + (f" (left out: {', '.join(left_out)}, alternative clips)" if left_out else "")])
    if report.get("viewing"):
        rows.append(["viewing (the AQM's, §6)", report["viewing"]])
    if report.get("store_size"):
        rows.append(["photon store", store_size_line(report["store_size"])])
    return _table(None, rows, left=2, cls="summary")


def _ranges(frames: list[int]) -> str:
    """1,2,3,5 -> '1-3,5' (farm syntax)."""
    parts, i = [], 0
    while i < len(frames):
        j = i
        while j + 1 < len(frames) and frames[j + 1] == frames[j] + 1:
            j += 1
        parts.append(str(frames[i]) if i == j else f"{frames[i]}-{frames[j]}")
        i = j + 1
    return ",".join(parts)


def _segments(out: Path, records: list[SegmentRecord], config: dict) -> str:
    rows = []
    for r in records:
        last = used_fmax_step(r)
        p = f"{last['p_me_back']:.2f} / {last['p_me_fwd']:.2f}" if last else "-"
        t = r.times_s
        rows.append([r.index, f"{r.start}-{r.end}", r.k, f"{r.n_frame:,}", r.fmax_text,
                     "-" if r.d_aqm is None else f"{r.d_aqm:.2f}" + (" (cap)" if r.capped else ""), p,
                     r.e_pilot_text, r.temporal,
                     "guided" if r.guided else "fixed", r.status,
                     ", ".join(f"{t.get(k, 0.0):.1f}" for k in ("init_s", "fmax_s", "n_frame_s", "frames_s"))])
    table = _table(["seg", "frames", "K", "N_frame", "F_max", "d_AQM %", "p_me back / fwd", "E pilot",
                    "collection", "chosen", "status", "s: init, F_max, N_frame, frames"], rows, cls="table1")
    steps = []
    for r in records:
        if r.n_frame_steps:
            steps.append(f"<li>segment {r.index}, N_frame steps (d_AQM at K {r.k}): "
                         + _e(", ".join(f"{s['n_frame']:,}: {s['d_aqm']:.2f} %" for s in r.n_frame_steps)) + "</li>")
        if r.window_fmax_steps:
            steps.append(f"<li>segment {r.index}, windows' F_max tried at N_frame {r.n_frame:,} (d_AQM at K): "
                         + _e(", ".join(f"{s['fmax']}: {s['d_aqm']:.2f} %" for s in r.window_fmax_steps)) + "</li>")
        if len(r.fmax_steps) > 1:
            steps.append(f"<li>segment {r.index}, F_max steps (p_me back/fwd): "
                         + _e(", ".join(f"{s['fmax']} ({s['p_me_back']:.2f}/{s['p_me_fwd']:.2f})"
                                        for s in r.fmax_steps)) + "</li>")
    capped = f"<p id=\"capped\">(cap): {_e(CAPPED_NOTE)}</p>" if any(r.capped for r in records) else ""
    return (table + capped + (f"<ul>{''.join(steps)}</ul>" if steps else "")
            + _segment_picture(records, config)
            + (_img(_fig6_plot(out, records, config), "fig6-plot", "Fig. 6: d_AQM against N_frame at each K; "
                    "p_me against F_max (§5.2.2-3)") if any(r.guided for r in records) else ""))


def _segment_picture(records: list[SegmentRecord], config: dict) -> str:
    """The plot of N_frame, F_max and d_AQM per segment, where there is something to plot: with
    fixed settings (``--photons N --fmax F``) every segment has the same two numbers and no d_AQM,
    which one sentence says (the plot of three flat lines cost 0.2 s of the render's serial end)."""
    settings = {(r.n_frame, r.fmax) for r in records}
    if any(r.guided for r in records) or len(settings) > 1:
        return _img(_per_segment_plot(records, config), "segment-plot",
                    "N_frame, F_max and d_AQM of each segment over the frames it covers")
    if not settings:
        return ""
    ((n_frame, fmax),) = settings
    return (f"<p id=\"segment-settings\">Fixed settings: N_frame {n_frame:,} photons a frame and F_max {fmax} in "
            f"every segment (<code>--photons</code>, <code>--fmax</code>); no AQM run, so nothing to plot "
            f"per segment.</p>")


def _per_segment_plot(records: list[SegmentRecord], config: dict) -> str:
    fig, (axes,) = figure(1, 3, (12.5, 3.4))
    for r in records:
        x = [r.start - 0.5, r.end + 0.5]
        colour = f"C{r.index % 10}"
        axes[0].plot(x, [r.n_frame] * 2, color=colour, lw=3)
        axes[1].plot(x, [r.fmax] * 2, color=colour, lw=3)
        if r.d_aqm is not None:
            axes[2].plot(x, [r.d_aqm] * 2, color=colour, lw=3)
            axes[2].plot([r.k], [r.d_aqm], "o", color=colour)
        for ax in axes:
            ax.axvline(r.k, color=colour, lw=0.8, ls=":")
    if "d_thr" in config:
        axes[2].axhline(100 * config["d_thr"], color="red", lw=1, label=f"d_thr = {100 * config['d_thr']:g} %")
        axes[2].legend(fontsize=8)
    axes[0].set(ylabel="N_frame (photons per frame)", title="N_frame per segment")
    n_frames = [r.n_frame for r in records]
    if n_frames and max(n_frames) > 10 * min(n_frames):  # a decade or more: ticks in range
        from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter  # heavy: only when drawing

        # Plain labels at 1, 2 and 5 a decade: the log axis' own are mathtext ("10^5"), whose
        # first parse cost 0.1 s of the render's serial end
        axes[0].set_yscale("log")
        axes[0].yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        axes[0].yaxis.set_major_formatter(FuncFormatter(_photon_count))
        axes[0].yaxis.set_minor_formatter(NullFormatter())
    elif n_frames:
        axes[0].set_ylim(0, 1.15 * max(n_frames))
    axes[1].set(ylabel="F_max (frames)", title="F_max per segment")
    axes[2].set(ylabel="d_AQM (%) at K", title="d_AQM per segment")
    if all(r.d_aqm is None for r in records):
        axes[2].text(0.5, 0.5, "fixed settings: no AQM run", ha="center", va="center", transform=axes[2].transAxes)
    for ax in axes:
        ax.set_xlabel("frame (dotted: K)")
        ax.grid(alpha=0.3)
    return _figure_uri(fig)


def _photon_count(value: float, _position=None) -> str:
    """A tick label of a photon count: 20k, 1.5M."""
    for scale, unit in ((1e6, "M"), (1e3, "k")):
        if value >= scale:
            return f"{value / scale:g}{unit}"
    return f"{value:g}"


def _fig6_plot(out: Path, records: list[SegmentRecord], config: dict) -> str:
    """Fig. 6, written as the render's ``segments/segments.png`` (drawn once: it is the same picture)
    and embedded."""
    path = plot_segments(records, out / "segments" / "segments.png", d_thr=config.get("d_thr"),
                         p_thr=config.get("p_thr"))
    return _png_uri(path.read_bytes())


def _costs(report: dict, records: list[SegmentRecord]) -> str:
    selection = set(report.get("frames", []))
    head = ["", "frames"] + [f"{row} (s/frame)" for row in ROWS] + ["read (MB/frame)", "written (MB/frame)"]
    rows = []
    for label, recs in [(f"segment {r.index}", [r]) for r in records] + [("all", records)]:
        n = sum(1 for r in recs for f in range(r.start, r.end + 1) if f in selection)
        if not n:
            rows.append([label, 0] + ["-"] * (len(ROWS) + 2))
            continue
        table = stage_table(recs)
        rows.append([label, n] + [f"{table['wall'][row] / n:.4f}" for row in ROWS]
                    + [f"{table['bytes'][k] / n / 1e6:.3f}" for k in ("read", "written")])
    size = report.get("store_size")
    note = ("<p class=\"muted\">Wall-clock seconds of each stage, as the segment records hold them from the "
            "run that did the segment, divided by its frames (stage split as in <code>loom bench render</code>). "
            "Steps 1-3 of segment i + 1 run in segment i's task (§5.2) and their photon tracing and AQM count "
            "there; a segment redone in part (frames found done) shows what that run spent. The I/O row's bytes: "
            "the photon store's per-batch counts and sums (and hit records, if kept) its tasks wrote and read, and "
            "the illumination maps written.</p>"
            + ("" if size is None else f"<p>{html.escape(store_size_line(size))}.</p>"))
    return _table(head, rows, left=1, cls="table2") + note + _img(_per_frame_plot(report, records), "frame-plot",
                                                                 "Per frame: compositing seconds, photons traced "
                                                                 "and mean collection window")


def _per_frame_plot(report: dict, records: list[SegmentRecord]) -> str:
    fig, (axes,) = figure(1, 3, (12.5, 3.2))
    times = report.get("frame_times_s", {})
    if times:
        f = sorted(int(k) for k in times)
        parts = (("load_s", "map load"), ("render_s", "ray tracing"), ("write_s", "tone map + files"))
        # One filled step area per part, not a bar per frame: hundreds of bars took a second to draw
        axes[0].stackplot(f, *[[times[str(i)].get(key, 0.0) for i in f] for key, _ in parts], step="mid",
                          labels=[label for _, label in parts])
        axes[0].legend(fontsize=7)
    else:
        axes[0].text(0.5, 0.5, "no frame composited by this run", ha="center", va="center",
                     transform=axes[0].transAxes)
    info = {int(k): v for r in records for k, v in r.frames.items()}
    f = sorted(info)
    if f:
        axes[1].plot(f, [info[i].get("photons", 0) for i in f], ".-")
        axes[2].plot(f, [info[i].get("window", 0) for i in f], ".-")
    axes[0].set(xlabel="frame", ylabel="s", title="compositing per frame")
    axes[1].set(xlabel="frame", ylabel="photons", title="photons per frame", ylim=(0, None))
    axes[2].set(xlabel="frame", ylabel="frames", title="mean collection window per frame")
    for ax in axes:
        ax.grid(alpha=0.3)
    return _figure_uri(fig)


def _windows(records: list[SegmentRecord]) -> str:
    have = [r for r in records if r.windows_at_k]
    if not have:
        return ("<p>No window distribution at K recorded: segments with fixed settings (<code>--photons N</code>) "
                "run no decision at K. The mean window of every frame is plotted under Table 2.</p>")
    cols = min(3, len(have))
    rows = (len(have) + cols - 1) // cols
    fig, axes = figure(rows, cols, (4.2 * cols, 3.0 * rows))
    for ax, r in zip(axes.ravel(), have):
        w = r.windows_at_k
        n = max(w["elements"], 1)
        x = list(range(len(w["back"])))
        ax.bar([i - 0.2 for i in x], [100 * c / n for c in w["back"]], width=0.4, label="preceding frames")
        ax.bar([i + 0.2 for i in x], [100 * c / n for c in w["fwd"]], width=0.4, label="following frames")
        ax.set(title=f"segment {r.index}: K = {r.k}, F_max = {r.fmax}", xlabel="frames collected",
               ylabel="% of elements hit")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    for ax in axes.ravel()[len(have):]:
        ax.axis("off")
    return _img(_figure_uri(fig), "windows-plot", "Fig. 5: how many frames before and after K each element "
                "collects photons from (Condition (1), §5.1), over the elements the segment's photons hit")


def _aqm_maps(out: Path, records: list[SegmentRecord]) -> str:
    items = []
    for r in records:
        picture = record_path(out, r.index).with_suffix(".aqm.png")
        if picture.is_file():
            d = f"{r.d_aqm:.2f} %" if r.d_aqm is not None else "?"
            items.append(_img(_png_uri(picture.read_bytes()), f"aqm-{r.index}",
                              f"segment {r.index}, K = {r.k}, N_frame {r.n_frame:,}: d_AQM {d}", cls="map"))
    if not items:
        return "<p>No AQM map: no segment was decided by the AQM (fixed settings).</p>"
    return ("<p class=\"muted\">I1(K) against I2(K), the even and odd photons' renderings: pixels above 1 JND "
            "marked on the frame (pipeline/aqm/visualize.py).</p><div class=\"maps\">" + "".join(items) + "</div>")


def _filmstrip(out: Path, frames: list[int]) -> str:
    from PIL import Image  # Pillow, only for the filmstrip

    present = [f for f in frames if frame_paths(out, f)[1].is_file()]
    if not present:
        return "<p>No frame PNG found.</p>"
    step = max(1, -(-len(present) // FILMSTRIP_FRAMES))
    picked = present[::step]
    if present[-1] not in picked:
        picked.append(present[-1])
    items = []
    for f in picked:
        with Image.open(frame_paths(out, f)[1]) as im:
            im = im.convert("RGB")
            if im.width > THUMB_WIDTH:
                im = im.resize((THUMB_WIDTH, max(1, round(im.height * THUMB_WIDTH / im.width))), Image.LANCZOS)
            buf = io.BytesIO()
            im.save(buf, format="JPEG", quality=85)
        items.append(_img(_png_uri(buf.getvalue(), "image/jpeg"), f"frame-{f}", f"frame {f}", cls="thumb"))
    return f"<div class=\"strip\">{''.join(items)}</div>"


def _video(out: Path, report: dict) -> str:
    video = out / "preview.mp4"
    if not video.is_file():
        return "<p>No preview.mp4.</p>"
    size = video.stat().st_size
    if size > VIDEO_EMBED_MAX:
        return (f"<p>preview.mp4 is {size / 2**20:.0f} MB, too large to embed: "
                f"<a href=\"preview.mp4\">preview.mp4</a> beside this file.</p>"
                f"<video controls width=\"640\" src=\"preview.mp4\"></video>")
    res = report.get("resolution", [640, 480])
    poster = _poster(out, report.get("frames", []))
    return (f"<video id=\"preview\" controls loop preload=\"auto\" width=\"{max(320, min(int(res[0]), 960))}\" "
            f"{poster}src=\"{_png_uri(video.read_bytes(), 'video/mp4')}\"></video>"
            f"<p class=\"muted\">preview.mp4, {size / 2**10:.0f} KB, embedded.</p>")


def _poster(out: Path, frames: list[int]) -> str:
    """The first frame as the video's poster attribute (shown before it plays), or nothing."""
    png = frame_paths(out, frames[0])[1] if frames else None
    return f"poster=\"{_png_uri(png.read_bytes())}\" " if png is not None and png.is_file() else ""


def _skipped(report: dict) -> str:
    skipped = report.get("skipped_work")
    if not skipped:
        return "<p>Not recorded by the render that wrote this report.json.</p>"
    lines = "".join(f"<li>{_e(line)}</li>" for line in summary_lines(skipped))
    rows = [[f, "; ".join(f"{i['what']}: {i['why']}" for i in items)]
            for f, items in sorted(skipped["per_frame"].items(), key=lambda kv: int(kv[0]))]
    table = _table(["frame", "skipped: why"], rows, left=2, cls="skips") if rows else "<p>Nothing skipped.</p>"
    return (f"<ul class=\"skip\">{lines}</ul><details><summary>per frame ({len(rows)} frames)</summary>"
            f"{table}</details>")


def _settings(report: dict) -> str:
    settings = report.get("settings")
    if not settings:
        return "<p>Not recorded by the render that wrote this report.json.</p>"
    job = settings.get("job", {})
    rows = [[k, json.dumps(v) if isinstance(v, (dict, list)) else v] for k, v in sorted(job.items())]
    config = [[k, v] for k, v in sorted(settings.get("config", {}).items())]
    return ("<h3>Render</h3>" + _table(["setting", "value"], rows, left=2, cls="settings")
            + "<h3>RenderConfig (pipeline/config.py)</h3>" + _table(["field", "value"], config, left=2,
                                                                    cls="config"))
