"""The segment records as pictures: the paper's Fig. 6 (d_AQM against N_frame at each K_i) and the
F_max steps of §5.2.2 (p_me both ways at each F_max tried), one PNG (``OUT/segments/segments.png``,
``loom segments OUT --plot FILE``)."""
from __future__ import annotations

import math
from pathlib import Path

from pipeline.segments.records import SegmentRecord

from .figures import figure, save_png


def plot_segments(records: list[SegmentRecord], path: str | Path, *, d_thr: float | None = None,
                  p_thr: float | None = None) -> Path:
    """Write the figure atomically and return its path."""
    fig, ((left, right),) = figure(1, 2, (10, 4))
    for r in records:
        colour = f"C{r.index % 10}"
        if r.n_frame_steps:
            n = [s["n_frame"] for s in r.n_frame_steps]
            d = [s["d_aqm"] for s in r.n_frame_steps]
            left.plot(n, d, "o-", color=colour,
                      label=f"K{r.index + 1} = frame {r.k}" + (" (cap)" if r.capped else ""))
        if r.fmax_steps:
            f = [s["fmax"] for s in r.fmax_steps]
            right.plot(f, [s["p_me_back"] for s in r.fmax_steps], "o-", color=colour,
                       label=f"K{r.index + 1} preceding")
            right.plot(f, [s["p_me_fwd"] for s in r.fmax_steps], "s--", color=colour,
                       label=f"K{r.index + 1} following")
    if d_thr is not None:
        left.axhline(100 * d_thr, color="red", lw=1, label=f"d_thr = {100 * d_thr:g} %")
    if p_thr is not None:
        right.axhline(p_thr, color="red", lw=1, label=f"p_thr = {p_thr:g}")
    left.set(xscale="log", xlabel="N_frame (photons per frame)", ylabel="d_AQM (% of pixels > 1 JND)",
             title="N_frame at the central frames (Fig. 6, §5.2.3)")
    from matplotlib.ticker import FuncFormatter  # heavy: only when drawing

    def short(n, _pos):  # 20k, 50k, 100k, ...: matplotlib's labelled minor log ticks overlap
        lead = n / 10 ** math.floor(math.log10(n)) if n > 0 else 0
        return "" if round(lead) not in (1, 2, 5) else (f"{n / 1e6:g}M" if n >= 1e6 else f"{n / 1e3:g}k")

    left.xaxis.set_major_formatter(FuncFormatter(short))
    left.xaxis.set_minor_formatter(FuncFormatter(short))
    right.set(xlabel="F_max (frames)", ylabel="p_me", ylim=(0, 1), title="Segment length (§5.2.2)")
    for ax in (left, right):
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    return save_png(fig, path)
