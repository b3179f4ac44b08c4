"""NVIDIA FLIP (Andersson et al., "FLIP: A Difference Evaluator for Alternating Images", HPG 2020; the
``flip-evaluator`` package, LDR) on frames as their PNGs show them: how ``loom bench spp`` and
``loom bench error`` compute it.

Both images of a pair are shown with the default look (pipeline/tonemap.py, filmic) at one adaptation
luminance, sRGB-encoded, and compared at the pixels per degree of the AQM's viewing conditions
(pipeline/perceived.py viewing_for), so FLIP and d_AQM judge a frame as one viewer sees it.
"""
from __future__ import annotations

from types import ModuleType

import numpy as np


def evaluator() -> ModuleType:
    """The ``flip_evaluator`` module, or a one-line LoomError saying how to install it (test extras)."""
    try:
        import flip_evaluator
    except ImportError:
        from pipeline.errors import LoomError

        raise LoomError("needs NVIDIA FLIP: pip install flip-evaluator (in the test extras: pip install -e '.[test]')",
                        field="flip-evaluator") from None
    return flip_evaluator


def shown(rgb: np.ndarray, adaptation: float) -> np.ndarray:
    """The frame as its PNG shows it: the default look, sRGB-encoded, float in [0, 1] (FLIP's LDR input)."""
    from pipeline.tonemap import ToneMapping, display_linear, srgb_encode

    return srgb_encode(display_linear(rgb, adaptation, ToneMapping())).astype(np.float32)


def frame_ppd(width: int, height: int) -> float:
    """Pixels per degree of a ``width`` x ``height`` frame under the AQM's default viewing conditions."""
    from pipeline.perceived import viewing_for
    from pipeline.tonemap import ToneMapping

    return viewing_for(ToneMapping()).frame_ppd((height, width))


def flip_mean(test: np.ndarray, reference: np.ndarray, ppd: float) -> float:
    """Mean FLIP error of two sRGB-encoded LDR images (H, W, 3) in [0, 1] at ``ppd`` pixels per degree."""
    _, mean, _ = evaluator().evaluate(np.ascontiguousarray(reference, np.float32),
                                      np.ascontiguousarray(test, np.float32), "LDR", inputsRGB=True,
                                      applyMagma=False, parameters={"ppd": float(ppd)})
    return float(mean)


def displayed_flip(test: np.ndarray, reference: np.ndarray, adaptation: float, ppd: float) -> float:
    """Mean FLIP error of two linear renderings (H, W, 3) of one frame, both shown at ``adaptation``."""
    return flip_mean(shown(test, adaptation), shown(reference, adaptation), ppd)
