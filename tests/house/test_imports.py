"""The import rules of docs/02-layout.md §3, checked on the source: no import cycle between modules,
no import from a higher layer, only pipeline/run imports Dask's ``distributed``, and every import
inside a function is on the allow list below with its reason.

The graph is read with ``ast``: module-level imports, imports inside functions and those under
``if TYPE_CHECKING`` all count. ``from pkg import name`` is an edge to the module ``pkg.name`` when
there is one, else to ``pkg`` (its ``__init__.py``).
"""
from __future__ import annotations

import ast
import fnmatch
from dataclasses import dataclass
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("pipeline", "workers", "kernels")

# docs/02-layout.md §3, lowest first: a module may import from its own layer and lower ones.
LAYERS = (
    ("kernels",),
    ("pipeline", "pipeline.errors", "pipeline.paths", "pipeline.config", "pipeline.stage_clock"),
    ("pipeline.scene",),
    ("pipeline.photons",),
    ("pipeline.store",),
    ("pipeline.collection",),
    ("pipeline.aqm",),
    ("pipeline.frames",),
    ("pipeline.segments",),
    ("workers",),
    ("pipeline.report",),
    ("pipeline.run",),
    ("pipeline.benchmarks",),
    ("pipeline.cli", "pipeline.__main__"),
)

# Imports allowed inside functions: (importing modules, imported module) glob patterns and why.
LOCAL_IMPORTS = (
    ("pipeline.cli.*", "*", "CLI start-up: `loom --help` and each command import only what that command runs"),
    ("kernels.*", "pyopencl", "loaded when a kernel runs: the NumPy twins import where no OpenCL platform does"),
    ("kernels.*", "kernels.context", "the OpenCL context module imports pyopencl (see above)"),
    ("pipeline.run.cluster", "dask", "`loom render` starts the worker fork server before the client pays for Dask"),
    ("pipeline.run.cluster", "distributed", "as dask: imported once a cluster is started"),
    ("*", "matplotlib*", "heavy; drawn only in a render's serial tail and by benchmarks"),
    ("*", "PIL*", "Pillow, only for the report's filmstrip"),
    ("*", "imageio_ffmpeg", "the ffmpeg binary's wrapper, only for the preview video"),
    ("*", "OpenImageIO", "heavy; only where textures or images are read or written"),
    ("pipeline.benchmarks.*", "torch", "bench-only environment (ColorVideoVDP)"),
    ("pipeline.benchmarks.*", "pycvvdp", "bench-only environment (ColorVideoVDP)"),
    ("pipeline.benchmarks.*", "flip_evaluator", "test extra: NVIDIA FLIP, only for `loom bench spp|error|elements`"),
)


@dataclass(frozen=True)
class Import:
    source: str  # importing module
    target: str  # imported module (ours or third-party)
    line: int
    local: bool  # inside a function


def _module(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


@cache
def _modules() -> dict[str, Path]:
    return {_module(p): p for r in PACKAGES for p in sorted((ROOT / r).rglob("*.py")) if "__pycache__" not in p.parts}


def _visit(node: ast.AST, mod: str, package: str, local: bool, found: list[Import]) -> None:
    mods = _modules()
    for child in ast.iter_child_nodes(node):
        inner = local or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
        if isinstance(child, ast.Import):
            found.extend(Import(mod, a.name, child.lineno, local) for a in child.names)
        elif isinstance(child, ast.ImportFrom):
            base = child.module or ""
            if child.level:
                up = package.split(".")[:len(package.split(".")) - (child.level - 1)]
                base = ".".join(up + ([child.module] if child.module else []))
            for a in child.names:
                sub = f"{base}.{a.name}"
                found.append(Import(mod, sub if sub in mods else base, child.lineno, local))
        _visit(child, mod, package, inner, found)


@cache
def _imports() -> tuple[Import, ...]:
    found: list[Import] = []
    for mod, path in _modules().items():
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        _visit(ast.parse(path.read_text()), mod, package, False, found)
    return tuple(found)


def _ours(name: str) -> bool:
    return name.split(".")[0] in PACKAGES


def _layer(mod: str) -> int:
    best = max(((len(p), i) for i, layer in enumerate(LAYERS) for p in layer if mod == p or mod.startswith(p + ".")),
               default=None)
    assert best is not None, f"{mod} is in no layer of docs/02-layout.md §3"
    return best[1]


def test_every_module_has_a_layer():
    for mod in _modules():
        _layer(mod)


def test_no_import_cycle_between_modules():
    graph: dict[str, set[str]] = {m: set() for m in _modules()}
    for imp in _imports():
        if _ours(imp.target) and imp.target != imp.source and imp.target in graph:
            graph[imp.source].add(imp.target)
    # Tarjan's strongly connected components, iteratively
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles = []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            w = next(children, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                scc = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    scc.append(w)
                    if w == v:
                        break
                if len(scc) > 1:
                    cycles.append(sorted(scc))
    assert not cycles, f"import cycles: {cycles}"


def test_no_import_goes_up_a_layer():
    upward = [f"{i.source}:{i.line} imports {i.target} ({LAYERS[_layer(i.target)][0]} is above "
              f"{LAYERS[_layer(i.source)][0]})"
              for i in _imports() if _ours(i.target) and _layer(i.target) > _layer(i.source)]
    assert not upward, "\n".join(upward)


def test_only_pipeline_run_imports_distributed():
    others = [f"{i.source}:{i.line}" for i in _imports()
              if i.target.split(".")[0] == "distributed" and not i.source.startswith("pipeline.run.")
              and not i.source.startswith("pipeline.benchmarks.")]
    assert not others, others


def _allowed(imp: Import) -> bool:
    return any(fnmatch.fnmatchcase(imp.source, src) and fnmatch.fnmatchcase(imp.target, tgt)
               for src, tgt, _reason in LOCAL_IMPORTS)


def test_function_local_imports_are_on_the_allow_list():
    hidden = [f"{i.source}:{i.line} {i.target}" for i in _imports() if i.local and not _allowed(i)]
    assert not hidden, "imports inside functions not on LOCAL_IMPORTS:\n" + "\n".join(hidden)


def test_every_allow_list_entry_is_used_and_has_a_reason():
    local = [i for i in _imports() if i.local]
    for src, tgt, reason in LOCAL_IMPORTS:
        assert reason.strip(), (src, tgt)
        assert any(fnmatch.fnmatchcase(i.source, src) and fnmatch.fnmatchcase(i.target, tgt) for i in local), \
            f"LOCAL_IMPORTS entry {src!r} {tgt!r} matches no import: remove it"
