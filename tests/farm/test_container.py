"""docker/Dockerfile and docker/compose.yaml, built and run by a real Docker engine (slow).

* for real, in containers: the image built by Debian's docker.io (from Docker Hub's base when it can
  be pulled, else a debootstrap stand-in: tests/farm/docker_engine.py), the compose file's scheduler,
  two workers and render client run as they are, and their frames equal a local `loom render`'s
  byte for byte;
* static: the Dockerfile's instructions (base image, Debian's pocl-opencl-icd, the wheel, the
  WORKER_ENV environment, the cache-warming step), every file it COPYs exists and is not ignored,
  the warmed programs are exactly those the tasks build and with the same options, and the compose
  file's services, commands and shared /data volume;
* outside docker: the Dockerfile's builder stage (a wheel from exactly the COPYed files), a fresh
  venv with that wheel, the Dockerfile's warming command with its ENV (PoCL's cache fills), the
  `dask scheduler` / `dask worker` commands the compose file runs, and `loom scene cornell` + a tiny
  `loom render`, all from a working directory outside the repository.
"""
from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from pipeline.run.cluster import WORKER_ENV

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
DOCKER = ROOT / "docker"


def instructions(path: Path) -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) of a Dockerfile, continuation lines joined, comments dropped."""
    out, buf = [], ""
    for line in path.read_text().splitlines():
        if not buf and (not line.strip() or line.lstrip().startswith("#")):
            continue
        if line.lstrip().startswith("#"):  # a comment inside a continued instruction
            continue
        if line.rstrip().endswith("\\"):
            buf += line.rstrip()[:-1] + " "
            continue
        buf += line
        word, _, rest = buf.strip().partition(" ")
        out.append((word.upper(), rest.strip()))
        buf = ""
    assert not buf, "Dockerfile ends inside a continued line"
    return out


def env_of(ins) -> dict[str, str]:
    env = {}
    for word, rest in ins:
        if word == "ENV":
            for item in shlex.split(rest):
                key, _, value = item.partition("=")
                env[key] = value
    return env


def copies(ins) -> list[tuple[list[str], str]]:
    """(sources, destination) of the COPY instructions that read the build context."""
    out = []
    for word, rest in ins:
        if word == "COPY":
            args = shlex.split(rest)
            if any(a.startswith("--from") for a in args):
                continue
            args = [a for a in args if not a.startswith("--")]
            out.append((args[:-1], args[-1]))
    return out


def dockerignore_keeps(rel: str) -> bool:
    """Whether docker/Dockerfile.dockerignore lets ``rel`` (or a file under it) into the context."""
    path = DOCKER / "Dockerfile.dockerignore"
    if not path.exists():
        return True
    kept = True
    for raw in path.read_text().splitlines():
        pat = raw.strip()
        if not pat or pat.startswith("#"):
            continue
        negate = pat.startswith("!")
        pat = pat.lstrip("!").rstrip("/")
        if pat == "*" or pat == rel or rel.startswith(pat + "/"):
            kept = negate
    return kept


# ---------------------------------------------------------------- static checks

def test_dockerfile_instructions():
    ins = instructions(DOCKER / "Dockerfile")
    args = dict(rest.split("=", 1) for word, rest in ins if word == "ARG" and "=" in rest)
    assert args.get("BASE") == "python:3.11-slim-bookworm"
    froms = [rest.split()[0].replace("${BASE}", args["BASE"]) for word, rest in ins if word == "FROM"]
    assert froms == ["python:3.11-slim-bookworm"] * 2, froms
    runs = " ".join(rest for word, rest in ins if word == "RUN")
    assert re.search(r"apt-get install .*--no-install-recommends.* pocl-opencl-icd", runs)
    assert "pip wheel --no-cache-dir --no-deps -w /wheels ." in runs
    assert "pip install --no-cache-dir /tmp/wheels/photonloom-" in runs
    env = env_of(ins)
    for key, value in WORKER_ENV.items():
        assert env.get(key) == value, f"ENV {key}={env.get(key)!r}, pipeline/run/cluster.py WORKER_ENV says {value!r}"
    assert env["POCL_CACHE_DIR"].startswith("/var/cache") and env["XDG_CACHE_HOME"] == "/var/cache"
    # The image keeps no checkout: only the builder stage copies the sources.
    final = ins[max(i for i, (w, _) in enumerate(ins) if w == "FROM"):]
    assert [src for src, _ in copies(final)] == [["docker/warm_kernels.py"]]


def test_every_copied_file_exists_and_reaches_the_build_context():
    ins = instructions(DOCKER / "Dockerfile")
    sources = [s for srcs, _ in copies(ins) for s in srcs]
    assert {"pyproject.toml", "README.md", "pipeline", "kernels", "workers", "docker/warm_kernels.py"} <= set(sources)
    for src in sources:
        assert (ROOT / src).exists(), f"COPY {src}: no such file in the repository"
        assert dockerignore_keeps(src), f"COPY {src}: excluded by docker/Dockerfile.dockerignore"
    for ignored in (".venv", "tests", "out"):
        assert not dockerignore_keeps(ignored)


def test_warmed_programs_are_the_ones_the_tasks_build():
    """Every kernel("program", "kernel") call in the shipped code names a program the image warms,
    and none passes build options (the warming builds with kernels.context's default, none)."""
    sys.path.insert(0, str(DOCKER))
    try:
        import warm_kernels
    finally:
        sys.path.remove(str(DOCKER))
    called, with_options = set(), []
    for package in ("kernels", "workers", "pipeline"):
        for path in (ROOT / package).rglob("*.py"):
            text = path.read_text()
            for m in re.finditer(r"\b(kernel|program)\(\s*\"(\w+)\"([^)]*)\)", text):
                fn, name, rest = m.groups()
                called.add(name)
                extra = [a for a in rest.split(",") if a.strip()]
                if len(extra) > (1 if fn == "kernel" else 0):
                    with_options.append(f"{path.relative_to(ROOT)}: {m.group(0)}")
    task_programs = called - {"sampling", "lanes", "philox"}
    assert task_programs == set(warm_kernels.WORKER_PROGRAMS), (task_programs, warm_kernels.WORKER_PROGRAMS)
    assert not with_options and warm_kernels.BUILD_OPTIONS == ()
    for name in warm_kernels.WORKER_PROGRAMS:
        assert (ROOT / "kernels" / f"{name}.cl").exists()
    # The Dockerfile runs the script it copies, at the path it copies it to.
    ins = instructions(DOCKER / "Dockerfile")
    dest = dict((srcs[0], d) for srcs, d in copies(ins))["docker/warm_kernels.py"]
    assert f"python {dest}" in " ".join(rest for word, rest in ins if word == "RUN")


def test_compose_services():
    compose = yaml.safe_load((DOCKER / "compose.yaml").read_text())
    services = compose["services"]
    assert set(services) == {"scheduler", "worker", "render"}
    assert services["scheduler"]["command"] == ["dask", "scheduler"]
    assert services["worker"]["command"] == ["dask", "worker", "tcp://scheduler:8786", "--nthreads", "1"]
    # Scalable with --scale worker=N: no fixed name, no host port.
    assert "container_name" not in services["worker"] and "ports" not in services["worker"]
    render = " ".join(services["render"]["command"])
    assert "loom scene cornell -o /data/cornell.glb &&" in render
    assert "loom render /data/cornell.glb --frames 1-12 --out /data/out --scheduler tcp://scheduler:8786" in render
    assert services["worker"]["depends_on"]["scheduler"]["condition"] == "service_healthy"
    for name, svc in services.items():
        assert svc["image"] == "photonloom:latest", name
        assert svc["volumes"] == ["data:/data"], name  # one volume, the same path everywhere
        build = svc["build"]
        assert (DOCKER / build["context"]).resolve() == ROOT and (ROOT / build["dockerfile"]).is_file()
    assert "data" in compose["volumes"]


def test_readme_paragraph_matches_compose():
    text = (ROOT / "README.md").read_text()
    assert "**Containers.**" in text, "the README must say what the image does and what was tested"
    start = text.index("**Containers.**")
    para = text[start:text.index("**Tested here**", start)]  # the paragraph and its command block
    assert "docker/Dockerfile" in para and "docker/compose.yaml" in para and "--scale worker=" in para
    compose = yaml.safe_load((DOCKER / "compose.yaml").read_text())
    commands = [" ".join(s["command"]) for s in compose["services"].values()]
    for quoted in re.findall(r"`((?:dask|loom) [^`]+)`", para):
        if "tcp://scheduler:8786" in quoted:
            assert any(quoted in c for c in commands), f"README's `{quoted}` is not in docker/compose.yaml"


# ---------------------------------------------------------------- the install steps, for real

def _run(cmd, cwd, env, timeout=300):
    result = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert result.returncode == 0, f"{shlex.join(map(str, cmd))}\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}"
    return result


@pytest.mark.timeout(900)
def test_dockerfile_steps_in_a_fresh_venv(tmp_path):
    assert ROOT not in tmp_path.parents
    ins = instructions(DOCKER / "Dockerfile")
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("PYTHON", "VIRTUAL_ENV", "POCL", "PYOPENCL", "XDG_CACHE"))}

    # The builder stage: exactly what it COPYs (minus ignored caches), then pip wheel there.
    src = tmp_path / "src"
    src.mkdir()
    for srcs, dest in copies(ins[:[i for i, (w, _) in enumerate(ins) if w == "FROM"][1]]):
        for s in srcs:
            target = src / Path(s).name if dest.endswith("/") else src / dest
            if (ROOT / s).is_dir():
                shutil.copytree(ROOT / s, target, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
            else:
                shutil.copy2(ROOT / s, target)
    wheels = tmp_path / "wheels"
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-cache-dir", "-w", str(wheels), "."], src, env)
    (wheel,) = wheels.glob("photonloom-*.whl")

    # The worker stage: a fresh venv (the image's python), the wheel and its dependencies.
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", str(venv)], tmp_path, env)
    py, bindir = venv / "bin" / "python", venv / "bin"
    _run([str(py), "-m", "pip", "install", "--quiet", "--disable-pip-version-check", str(wheel)], tmp_path, env, 600)
    work = tmp_path / "work"
    work.mkdir()
    env = {**env, **env_of(ins), "PATH": f"{bindir}{os.pathsep}{env.get('PATH', '')}", "VIRTUAL_ENV": str(venv)}
    env["POCL_CACHE_DIR"] = str(tmp_path / "pocl")
    env["XDG_CACHE_HOME"] = str(tmp_path / "cache")
    where = _run([str(py), "-c", "import kernels, pipeline, workers, pathlib; "
                  "k = pathlib.Path(kernels.__file__).parent;"
                  "print(k); print(*sorted(p.name for p in k.glob('*.cl')))"], work, env).stdout.splitlines()
    assert Path(where[0]).is_relative_to(venv), where  # the installed package, not the checkout
    assert set(where[1].split()) == {p.name for p in (ROOT / "kernels").glob("*.cl")}  # the wheel has the kernels

    # The Dockerfile's warming command, the script mapped from where the image has it.
    warm = next(re.search(r"python (\S*warm_kernels\.py)", rest) for word, rest in ins
                if word == "RUN" and "warm_kernels.py" in rest)
    script = {d: s[0] for s, d in copies(ins)}[warm.group(1)]
    out = _run([str(py), str(ROOT / script)], work, env).stdout
    assert "PoCL kernel cache" in out
    assert any(p.is_file() for p in (tmp_path / "pocl").rglob("*")), "the PoCL kernel cache is empty"
    binaries = {p.name.split("-")[0] for p in (tmp_path / "cache" / "photonloom" / "opencl").glob("*.bin")}
    assert binaries >= {"emit", "scatter", "temporal", "gather", "filter", "camera", "surface"}, binaries
    # The Dockerfile's chmod after warming names cache folders that warming made (else the build fails).
    image_env = env_of(ins)
    chmod = re.search(r"chmod -R \S+ ([^&]+)", next(r for w, r in ins if w == "RUN" and "warm_kernels" in r))
    for folder in chmod.group(1).split():
        local = folder.replace(image_env["POCL_CACHE_DIR"], env["POCL_CACHE_DIR"])
        local = local.replace(image_env["XDG_CACHE_HOME"], env["XDG_CACHE_HOME"])
        assert Path(local).is_dir(), f"the Dockerfile's chmod names {folder}, which warming did not make"

    # The compose file's commands exist in the install, and loom renders from outside the checkout.
    for service in ("scheduler", "worker"):
        _run([str(bindir / "dask"), service, "--help"], work, env, 120)
    _run([str(bindir / "loom"), "scene", "cornell", "-o", "cornell.glb"], work, env)
    _run([str(bindir / "loom"), "render", "cornell.glb", "--out", "out", "--scheduler", "synchronous",
          "--frames", "1-2", "--resolution", "32x24", "--spp", "1", "--photons", "2000"], work, env)
    for f in (1, 2):
        assert (work / "out" / f"beauty.{f:04d}.exr").stat().st_size > 0
        assert (work / "out" / f"beauty.{f:04d}.png").stat().st_size > 0


# ---------------------------------------------------------------- the image and compose, for real

@pytest.mark.timeout(1800)
def test_the_image_builds_and_compose_renders_cornell_as_loom_render_does(tmp_path):
    """docker/Dockerfile built by a real Docker engine, docker/compose.yaml's scheduler, two workers
    and render client run as they are, and the frames they write equal a local `loom render`'s of
    the same command, byte for byte."""
    import tarfile

    from pipeline.frames.images import frame_paths
    from pipeline.segments.records import read_records
    from tests.farm.docker_engine import base_image, compose_command, ensure_engine

    ensure_engine(tmp_path / "dockerd.log")
    base = base_image(tmp_path)

    # The build context: the files the Dockerfile COPYs, as docker/Dockerfile.dockerignore keeps them
    ins = instructions(DOCKER / "Dockerfile")
    context = tmp_path / "context.tar"
    with tarfile.open(context, "w", format=tarfile.GNU_FORMAT) as tar:  # PAX headers: docker reads a Dockerfile
        for src in ["docker/Dockerfile", *(s for srcs, _ in copies(ins) for s in srcs)]:
            tar.add(ROOT / src, arcname=src, filter=lambda t: None if "__pycache__" in t.name or
                    t.name.endswith(".pyc") else t)
    with open(context, "rb") as stdin:
        built = subprocess.run(["docker", "build", "-f", "docker/Dockerfile", "--build-arg", f"BASE={base}",
                                "-t", "photonloom:latest", "-"], stdin=stdin, capture_output=True, text=True)
    assert built.returncode == 0, built.stdout[-3000:] + built.stderr[-3000:]

    project = f"loomtest{os.getpid()}"
    compose = [*compose_command(), "-p", project, "-f", str(DOCKER / "compose.yaml")]
    try:
        up = subprocess.run([*compose, "up", "--no-build", "--scale", "worker=2", "--exit-code-from", "render"],
                            capture_output=True, text=True, timeout=900)
        assert up.returncode == 0, up.stdout[-4000:] + up.stderr[-2000:]
        assert "12 frames written" in up.stdout
        got = tmp_path / "volume"
        got.mkdir()
        subprocess.run(["docker", "run", "--rm", "-v", f"{project}_data:/data", "-v", f"{got}:/out",
                        "photonloom:latest", "cp", "-r", "/data/out", "/data/cornell.glb", "/out/"],
                       check=True, capture_output=True)
    finally:
        subprocess.run([*compose, "down", "-v"], capture_output=True, timeout=300)

    # The same commands here: the scene (same bytes), then the render on a local cluster
    here = tmp_path / "here"
    here.mkdir()
    loom = [sys.executable, "-m", "pipeline"]
    subprocess.run([*loom, "scene", "cornell", "-o", here / "cornell.glb"], check=True, capture_output=True)
    assert (here / "cornell.glb").read_bytes() == (got / "cornell.glb").read_bytes()
    subprocess.run([*loom, "render", here / "cornell.glb", "--frames", "1-12", "--out", here / "out", "--workers", "2",
                    "--quiet"], check=True, capture_output=True)
    for f in range(1, 13):
        for mine, theirs in zip(frame_paths(here / "out", f), frame_paths(got / "out", f)):
            assert mine.read_bytes() == theirs.read_bytes(), f"frame {f}: {theirs.name} differs"
    records = [[r.without_times() for r in read_records(out / "out")] for out in (got, here)]
    assert records[0] == records[1]
    assert (got / "out" / "preview.mp4").stat().st_size > 0 and (got / "out" / "report.html").is_file()
