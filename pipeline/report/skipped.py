"""What a render did not do, frame by frame, and why (``report.json`` "skipped_work", the report).

Work a production renderer should skip, and says it skipped:

* photon tracing of a frame whose scene state (geometry and lights) equals an earlier frame's:
  where nothing but the camera moves, it shares that frame's photons (pipeline/store, ``source_frame``);
* reflection rays where no mirror or glossy surface is in view (the compositor casts them only
  from specular hits, workers/composite.py), and in every frame of a scene without one;
* area-light sampling in a scene without emissive triangles or a sky (a sky is sampled like an
  area light, pipeline/frames/area_lights.py, and its rays are counted as area rays);
* segments a rerun found done (record current, every frame valid) and frames whose files carry
  their current frame hash (pipeline/run/coordinator.py ``segment_done``, ``composite_calls``);
* the photons of segments without indirect light: no photon of theirs recorded any, so they stay on
  the smallest rung of N_frame (pipeline/segments/decisions.py ``unlit_n_frame``).

Pure: it reads the scene's flags, the store's sharing table and the counts the render returned.
"""
from __future__ import annotations

from typing import Sequence

SHARED = "photons"
REFLECTION = "reflection rays"
AREA = "area-light sampling"
DONE = "frame"


def skipped_work(frames: Sequence[int], *, sources: dict[int, int], has_specular: bool, has_area_lights: bool,
                 rays: dict[int, dict] | None, segments_done: list[dict], has_sky: bool = False,
                 segments_unlit: Sequence[dict] = ()) -> dict:
    """The skipped work of a render of ``frames``: ``sources`` maps each frame to the frame whose
    photons it uses, ``rays`` the ray counts per kind of the frames written by this run (frames
    absent were already done; None: written by other processes, a farm's recipes, so unknown),
    ``segments_done`` the records ({index, frames}) a rerun skipped; ``has_sky``: the scene has a
    sky emitter, sampled as an area light; ``segments_unlit`` ({index, frames, n_frame}) the
    segments without indirect light."""
    per_frame: dict[str, list[dict]] = {}
    for f in frames:
        items = []
        if sources[f] != f:
            items.append({"what": SHARED,
                          "why": f"nothing but the camera moves since frame {sources[f]}: shares its photons"})
        if rays is not None and f not in rays:
            items.append({"what": DONE, "why": "already done: its files carry the current frame hash"})
        seen = None if rays is None else rays.get(f)  # ray counts: known for the frames written here
        if not has_specular:
            items.append({"what": REFLECTION, "why": "no mirror or glossy material in the scene"})
        elif seen is not None and seen.get("reflection", 0) == 0:
            items.append({"what": REFLECTION, "why": "no specular surface in view"})
        if not has_area_lights and not has_sky:
            items.append({"what": AREA, "why": "no emissive triangles and no sky in the scene"})
        elif seen is not None and seen.get("area", 0) == 0:
            items.append({"what": AREA, "why": "no diffuse surface in view takes area or sky light"})
        if items:
            per_frame[str(f)] = items
    counts: dict[str, int] = {}
    for items in per_frame.values():
        for item in items:
            counts[item["what"]] = counts.get(item["what"], 0) + 1
    distinct = len({sources[f] for f in frames})
    return {"per_frame": per_frame, "frames_skipping": counts, "segments_done": segments_done,
            "segments_unlit": list(segments_unlit),
            "photon_sets": distinct, "frames": len(list(frames))}


def summary_lines(skipped: dict) -> list[str]:
    """One line a kind of skipped work, for the report and the terminal."""
    n = skipped["frames"]
    counts = skipped["frames_skipping"]
    lines = [f"photon sets traced: {skipped['photon_sets']} for {n} frames"
             + (" (one set for the whole animation: nothing in it moves but the camera)"
                if skipped["photon_sets"] == 1 and n > 1 else "")]
    for what, label in ((SHARED, "frames sharing another frame's photons (nothing but the camera moves)"),
                        (REFLECTION, "frames casting no reflection rays"),
                        (AREA, "frames with no area-light sampling"),
                        (DONE, "frames already done (kept as they were)")):
        lines.append(f"{label}: {counts.get(what, 0)} of {n}")
    unlit = skipped.get("segments_unlit", [])
    lines.append(f"segments without indirect light (N_frame the smallest rung): {len(unlit)}"
                 + (" (" + ", ".join(f"{s['index']}: frames {s['frames'][0]}-{s['frames'][1]} at {s['n_frame']:,}"
                                     for s in unlit) + ")" if unlit else ""))
    segs = skipped["segments_done"]
    lines.append(f"segments already done: {len(segs)}"
                 + (" (" + ", ".join(f"{s['index']}: frames {s['frames'][0]}-{s['frames'][1]}" for s in segs) + ")"
                    if segs else ""))
    return lines
