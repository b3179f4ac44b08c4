"""Every generated case (tests/robustness/cases.py) through ``loom info`` and a tiny ``loom render``:
a one-line error naming the problem or correct output, no traceback, no hang, peak memory < 1 GB,
and nothing left behind by a render that was refused.

The cases run in batches in child processes (tests/robustness/harness.py): one for ``loom info``
and one for ``loom render``, each job under a SIGALRM time limit and the process under an
address-space limit; the process's peak resident memory bounds every job's. The renders of the
valid scenes that take longest (the 100,000-frame timeline) are in the slow sweep.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.robustness.cases import TINY_RENDER, all_cases, base_builder

ROOT = Path(__file__).resolve().parents[2]
PEAK_LIMIT = 1 << 30  # 1 GiB resident, per job (the batch's peak bounds each job's)
INFO_ADDRESS_SPACE = 3 << 30  # no OpenCL in `loom info`: a runaway allocation fails early
RENDER_ADDRESS_SPACE = 12 << 30  # PoCL and Embree reserve address space they never touch
INFO_TIMEOUT_S = 20
RENDER_TIMEOUT_S = 120
SLOW_RENDERS = {"100,000 frames"}
CASES = all_cases()


def _write(tmp: Path) -> dict:
    """Every case's scene in its own folder; command-line cases use the base scene."""
    (tmp / "base").mkdir()
    base = base_builder().write(tmp / "base" / "scene.glb")
    scenes = {}
    for i, case in enumerate(CASES):
        if case.make is None:
            scenes[case.name] = base
            continue
        folder = tmp / f"case{i:03d}" / "scene"
        folder.mkdir(parents=True)
        scenes[case.name] = case.make(folder)
    return scenes


def _run_batch(tmp: Path, name: str, jobs: list[dict], address_space: int) -> tuple[dict, int]:
    path = tmp / f"{name}.json"
    path.write_text(json.dumps(jobs))
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, "-m", "tests.robustness.harness", "--address-space",
                           str(address_space), str(path)], capture_output=True, text=True, env=env, cwd=tmp,
                          timeout=sum(j["timeout"] for j in jobs) + 60)
    lines = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
    assert proc.returncode == 0 and lines and "peak_bytes" in lines[-1], proc.stderr[-3000:]
    return {r["name"]: r for r in lines[:-1]}, lines[-1]["peak_bytes"]


def _render_argv(case, scene, out):
    return ["render", str(scene), "--out", str(out), *TINY_RENDER, *(case.render_args or [])]


@pytest.fixture(scope="module")
def batches(tmp_path_factory, request):
    marks = str(request.config.getoption("-m") or "")
    slow = "slow" in marks and "not slow" not in marks
    tmp = tmp_path_factory.mktemp("hostile")
    scenes = _write(tmp)
    info_jobs = [{"name": c.name, "argv": ["info", str(scenes[c.name]), *c.info_args], "timeout": INFO_TIMEOUT_S}
                 for c in CASES if c.command in (None, "info")]
    outs = {c.name: tmp / "out" / f"r{i:03d}" for i, c in enumerate(CASES)}
    render_jobs = [{"name": c.name, "argv": _render_argv(c, scenes[c.name], outs[c.name]),
                    "timeout": RENDER_TIMEOUT_S}
                   for c in CASES if c.command in (None, "render") and (slow or c.name not in SLOW_RENDERS)]
    info, info_peak = _run_batch(tmp, "info", info_jobs, INFO_ADDRESS_SPACE)
    render, render_peak = _run_batch(tmp, "render", render_jobs, RENDER_ADDRESS_SPACE)
    return {"info": info, "render": render, "peaks": (info_peak, render_peak), "outs": outs}


def test_there_are_at_least_sixty_cases():
    assert len(CASES) >= 60
    assert len({c.name for c in CASES}) == len(CASES)


def test_peak_memory_is_under_one_gigabyte(batches):
    info_peak, render_peak = batches["peaks"]
    assert info_peak < PEAK_LIMIT, f"loom info batch peaked at {info_peak / 2**20:.0f} MiB"
    assert render_peak < PEAK_LIMIT, f"loom render batch peaked at {render_peak / 2**20:.0f} MiB"


def _check(case, result):
    assert result["traceback"] is None, result["traceback"]
    assert not result["hang"], f"{case.name}: ran past its time limit"
    errors = [line for line in result["stderr"] if line.startswith("loom: error:")]
    if case.expect == "ok":
        assert result["code"] == 0 and not errors, result["stderr"]
        return
    assert result["code"] == 2, (result["code"], result["stderr"])
    others = [line for line in result["stderr"] if not line.startswith(("loom: WARNING", "loom: error:"))]
    assert len(errors) == 1 and not others, result["stderr"]
    assert case.says in errors[0], f"{case.name}: {errors[0]!r} does not say {case.says!r}"


@pytest.mark.parametrize("case", [c for c in CASES if c.command in (None, "info")], ids=lambda c: c.name)
def test_loom_info(batches, case):
    result = batches["info"][case.name]
    _check(case, result)
    if case.expect == "ok":
        assert "frames " in result["stdout"] and "elements " in result["stdout"]


@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow) if c.name in SLOW_RENDERS else c
                                  for c in CASES if c.command in (None, "render")], ids=lambda c: c.name)
def test_tiny_render(batches, case):
    result = batches["render"][case.name]
    _check(case, result)
    out = batches["outs"][case.name]
    if case.expect == "ok":
        assert (out / "report.json").exists() and list(out.glob("beauty.*.exr"))
        assert not list(out.rglob("*.partial*"))
    elif "/proc" not in case.name:
        assert not out.exists(), f"{case.name}: a refused render left {sorted(out.rglob('*'))[:5]}"
