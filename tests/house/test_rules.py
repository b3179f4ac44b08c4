"""House rules a newcomer can rely on, checked on the source itself so they stay true: kernels sit
below the pipeline, each fact has one owner, public functions carry type hints, no function takes
more than a handful of parameters and the layout note (docs/02-layout.md) names every module (the
README and citations: tests/house/test_readme.py)."""
from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("pipeline", "kernels", "workers")
# Decorators that make a function a click command: click types its parameters itself.
CLICK_DECORATORS = {"command", "group", "option", "argument", "pass_context", "pass_obj"}


def _sources(*roots: str, suffixes: tuple[str, ...] = (".py",)) -> list[Path]:
    return sorted(p for r in roots for p in (ROOT / r).rglob("*")
                  if p.suffix in suffixes and "__pycache__" not in p.parts)


def _rel(path: Path) -> str:
    return path.relative_to(ROOT).as_posix()


def test_kernels_import_nothing_from_the_pipeline_or_the_workers():
    """kernels/ is the bottom layer: it may not import pipeline/ or workers/."""
    found = []
    for path in _sources("kernels"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0 else []
            found += [f"{_rel(path)}:{node.lineno} {n}" for n in names if n.split(".")[0] in ("pipeline", "workers")]
    assert not found, found


def _decorator_name(node: ast.expr) -> str:
    node = node.func if isinstance(node, ast.Call) else node
    return node.attr if isinstance(node, ast.Attribute) else getattr(node, "id", "")


def _public_functions(tree: ast.Module):
    """(name, node) of module-level functions and methods of public classes not starting with _."""
    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)) and not child.name.startswith("_"):
                yield prefix + child.name, child
            elif isinstance(child, ast.ClassDef) and not child.name.startswith("_"):
                yield from visit(child, prefix + child.name + ".")
    yield from visit(tree, "")


def test_public_functions_have_type_hints():
    """Every parameter and the return of every public function is annotated (click commands aside)."""
    missing = []
    for path in _sources(*PACKAGES):
        for name, fn in _public_functions(ast.parse(path.read_text())):
            if {_decorator_name(d) for d in fn.decorator_list} & CLICK_DECORATORS:
                continue
            a = fn.args
            params = [p for p in a.posonlyargs + a.args + a.kwonlyargs if p.arg not in ("self", "cls")]
            params += [p for p in (a.vararg, a.kwarg) if p is not None]
            gaps = [p.arg for p in params if p.annotation is None] + (["return"] if fn.returns is None else [])
            if gaps:
                missing.append(f"{_rel(path)}:{fn.lineno} {name}: {', '.join(gaps)}")
    assert not missing, "\n".join(missing)


MAX_PARAMETERS = 8  # docs/02-layout.md §4
# Exempt from MAX_PARAMETERS: the CLI's commands take one parameter per click option, the glTF
# builder's add_* helpers mirror the glTF fields, and the benchmarks spell out what they measure.
PARAMETER_EXEMPT = ("pipeline/cli/", "pipeline/benchmarks/", "pipeline/scene/builtin/gltf_builder.py")
# Functions allowed more parameters than MAX_PARAMETERS, as "path qualified.name": reason.
MANY_PARAMETERS: dict[str, str] = {}


def _parameter_counts(tree: ast.Module, where: str):
    """("where:line qualified.name", count) of every function and method in ``tree``, nested ones
    too, counting positional, keyword-only, *args and **kwargs parameters but not self or cls."""
    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                a = child.args
                params = [p for p in a.posonlyargs + a.args + a.kwonlyargs if p.arg not in ("self", "cls")]
                params += [p for p in (a.vararg, a.kwarg) if p is not None]
                yield f"{where}:{child.lineno} {prefix}{child.name}", len(params)
                yield from visit(child, f"{prefix}{child.name}.")
            elif isinstance(child, ast.ClassDef):
                yield from visit(child, f"{prefix}{child.name}.")
            else:
                yield from visit(child, prefix)
    yield from visit(tree, "")


def _too_many(tree: ast.Module, where: str) -> list[str]:
    return [f"{name} takes {n} parameters" for name, n in _parameter_counts(tree, where)
            if n > MAX_PARAMETERS and f"{where} {name.split(' ', 1)[1]}" not in MANY_PARAMETERS]


def test_no_function_takes_more_than_a_handful_of_parameters():
    """Parameters that travel together are one small typed object (a request, the RenderSettings,
    the Job); a mode flag that selects another computation is another function."""
    found = []
    for path in _sources("pipeline", "workers"):
        if not _rel(path).startswith(PARAMETER_EXEMPT):
            found += _too_many(ast.parse(path.read_text()), _rel(path))
    assert not found, f"more than {MAX_PARAMETERS} parameters:\n" + "\n".join(found)


def test_the_parameter_count_names_the_offender():
    source = ("class Task:\n"
              "    def run(self, a, b, c, d, e, f, g, h, *, i):\n"
              "        def inner(a, b, c, d, e, f, g, *rest, **options): ...\n"
              "    def fits(self, a, b, c, d, e, f, g, h): ...\n")
    assert _too_many(ast.parse(source), "workers/example.py") == [
        "workers/example.py:2 Task.run takes 9 parameters", "workers/example.py:3 Task.run.inner takes 9 parameters"]


def test_every_parameter_exception_is_needed_and_has_a_reason():
    counts = {f"{_rel(p)} {name.split(' ', 1)[1]}": n for p in _sources("pipeline", "workers")
              for name, n in _parameter_counts(ast.parse(p.read_text()), _rel(p))}
    for name, reason in MANY_PARAMETERS.items():
        assert reason.strip(), name
        assert counts.get(name, 0) > MAX_PARAMETERS, f"MANY_PARAMETERS entry {name!r} is not needed: remove it"


# Each fact, the pattern that defines it, and its one owner.
FACTS = {
    "Rec. 709 luma weights": (r"0\.2126", "kernels/colour.py"),
    "record key bits": (r"^\s*PARITY_BIT\s*=|^\s*DIRECT_BIT\s*=|#define\s+PARITY_BIT", "kernels/record_layout.py"),
    "barycentric scale": (r"^\s*BARY_SCALE\s*=|#define\s+BARY_SCALE", "kernels/record_layout.py"),
    "ray kinds": (r"^\s*RAY_KINDS\s*=", "pipeline/frames/camera_paths.py"),
    "glTF component types": (r"5126\s*:", "pipeline/scene/gltf.py"),
    "glTF type widths": (r"\"MAT4\"\s*:\s*16", "pipeline/scene/gltf.py"),
    "writable-folder check": (r"os\.access\(", "pipeline/paths.py"),
}


@pytest.mark.parametrize("fact", sorted(FACTS))
def test_each_fact_has_one_owner(fact):
    pattern, owner = FACTS[fact]
    regex = re.compile(pattern)
    places = sorted({_rel(p) for p in _sources(*PACKAGES, "tests", suffixes=(".py", ".cl"))
                     if p != Path(__file__).resolve() and any(regex.search(ln) for ln in p.read_text().splitlines())})
    assert len(places) == 1, f"{fact} defined in {places}"
    assert owner is None or places == [owner], f"{fact} defined in {places}, expected {owner}"


LAYOUT = ROOT / "docs" / "02-layout.md"


def _layout_block() -> str:
    return LAYOUT.read_text().split("```", 2)[1]


def test_layout_names_every_module_and_nothing_that_is_gone():
    block = _layout_block()
    named = set(re.findall(r"[\w./-]+\.(?:py|cl)\b", block))
    modules = [p for p in _sources(*PACKAGES, suffixes=(".py", ".cl")) if p.name not in ("__init__.py", "__main__.py")]
    unnamed = [_rel(p) for p in modules if p.name not in {Path(n).name for n in named} and _rel(p) not in named]
    assert not unnamed, f"docs/02-layout.md does not name: {unnamed}"
    paths = [n for n in re.findall(r"[\w.-]+(?:/[\w.-]*)+", block) if n.split("/")[0] in PACKAGES + ("docs", "tests")]
    gone = [n for n in paths if not (ROOT / n).exists()]
    assert not gone, f"docs/02-layout.md names paths that do not exist: {gone}"
    basenames = {Path(n).name for n in named if "/" not in n}
    known = {p.name for p in modules}
    assert basenames <= known, f"docs/02-layout.md names modules that do not exist: {sorted(basenames - known)}"
