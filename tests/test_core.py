"""lobeview's ground floor: the method grammar (every name the program prints parses back to the
same method), the command lines F12 and shot print (pasted back through the real parser), the
bounded cache, and the import graph (layers point one way, no cycles, core imports nothing)."""

from __future__ import annotations

import ast
import shlex
from pathlib import Path

import pytest

from lobeview.core.cache import BoundedCache
from lobeview.core.methods import (
    MAX_PATTERN,
    MAX_SAMPLES,
    PREFILTER_MODES,
    Method,
    MethodError,
    method_choice,
    method_cli_flags,
    method_from_choice,
    realtime_choices,
    resolve_cli_method,
)

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("core", "materials", "scenes", "viewer", "app", "bench")


def _all_methods():
    for kind in ("lobe", "fis", "mc"):
        for n in (1, 2, 7, 11, MAX_PATTERN if kind == "lobe" else MAX_SAMPLES):
            yield Method(kind, n)
    for n in (1, 5, 19, MAX_PATTERN):
        yield Method("lobe", n, normalize=True)
    for n in (1, 15):
        yield Method("lobe", n, weighting="eq4.24")
    for n, normalize, weighting in ((3, False, "eq4.25"), (15, True, "eq4.25"), (19, False, "eq4.24")):
        yield Method("lobe", n, normalize, weighting=weighting, pattern="ring")
    for n in (7, 11):
        yield Method("lobe", n, normalize=True, pattern="fitted")
    yield Method.parse("reference")
    for mode in PREFILTER_MODES:
        yield Method("prefiltered", 1, mode=mode)


@pytest.mark.parametrize("method", list(_all_methods()), ids=str)
def test_every_method_round_trips_through_its_name(method):
    assert Method.parse(str(method)) == method
    assert str(Method.parse(str(method))) == str(method)


def test_the_names_the_program_uses_are_canonical():
    """Every method list of the benchmark, the stress grid, the panel and the docs' examples parses,
    and prints back as written (one spelling per method: the bench's 'lobe-7+norm' is the
    viewer's normalised lobe-7)."""
    from lobeview.bench import matrix_config as bench
    from lobeview.bench import stress

    names = [
        *bench.FULL_METHODS,
        *bench.QUICK_METHODS,
        *bench.SWEEP_METHODS,
        *stress.FULL_METHODS,
        *realtime_choices()[3:],
        "lobe-11",
        "lobe-11+norm",
        "prefiltered-multi",
    ]
    for name in names:
        assert str(Method.parse(name)) == name
    assert Method.parse("lobe-7+norm") == Method("lobe", 7, normalize=True)
    assert Method.parse("lobe-15+eq4.24") == Method("lobe", 15, weighting="eq4.24")
    assert Method.parse("lobe-15+eq4.24").family == "lobe+eq4.24"
    assert Method.parse("lobe-15+norm+ring") == Method("lobe", 15, normalize=True, pattern="ring")
    assert Method.parse("lobe-15+norm+ring").family == "lobe+norm+ring"
    assert Method.parse("lobe-15+norm+ring").with_samples(7).pattern == "ring"
    assert method_from_choice("lobe", 15, True, "ring") == Method.parse("lobe-15+norm+ring")
    assert method_from_choice("fis", 16, True, "ring") == Method.parse("fis-16")  # the checkbox is lobe-N's
    assert method_from_choice("lobe", 7, True, "fitted") == Method.parse("lobe-7+norm+fit")
    assert method_from_choice("lobe", 7, False, "fitted") == Method.parse("lobe-7")  # fitted reads need +norm


@pytest.mark.parametrize(
    "text",
    ["lobe-0", f"lobe-{MAX_PATTERN + 1}", "fis-0", f"mc-{MAX_SAMPLES + 1}", "fis-8+norm", "reference-64",
     "fis-8+eq4.24", "lobe-7+norm+eq4.24", "lobe-7+eq4.24+norm", "lobe-7+eq424",
     "fis-16+ring", "lobe-7+ring+norm", "lobe-7+ring+ring", "prefiltered+ring",
     "prefiltered-auto", "prefiltered-nope", "Lobe-3", "lobe-11 (normalised)", "lobe", ""],
)  # fmt: skip
def test_names_outside_the_grammar_are_refused(text):
    with pytest.raises(MethodError):
        Method.parse(text)


def test_invalid_methods_cannot_be_constructed():
    for bad in (dict(kind="fis", samples=4, normalize=True), dict(kind="lobe", samples=0),
                dict(kind="prefiltered", samples=1, mode="nope"), dict(kind="mc", samples=4, mode="lobe"),
                dict(kind="ray", samples=1), dict(kind="fis", samples=4, weighting="eq4.24"),
                dict(kind="lobe", samples=4, normalize=True, weighting="eq4.24"),
                dict(kind="lobe", samples=4, weighting="eq4.23")):  # fmt: skip
        with pytest.raises(MethodError):
            Method(**bad)


def _resolve_args(args) -> Method:
    from lobeview.app.options import resolve_method_args

    return resolve_method_args(args)


def test_command_line_fitted_reads_rule():
    """A bare lobe-N is lobe-N+norm+fit where N has a fitted table (issue 45: the default), the
    thesis pattern with --no-lobe-fit or where N has none; a suffix is taken as written."""
    counts = (3, 7, 11)
    fitted = Method("lobe", 11, normalize=True, pattern="fitted")
    assert resolve_cli_method("lobe-11", None, None, counts) == fitted
    assert resolve_cli_method("lobe-11", True, True, counts) == fitted
    assert resolve_cli_method("lobe-11+norm+fit", None, None, counts) == fitted
    assert resolve_cli_method("lobe-11", None, False, counts) == Method("lobe", 11, normalize=True)
    assert resolve_cli_method("lobe-9", None, None, counts) == Method("lobe", 9, normalize=True)  # no table
    assert resolve_cli_method("lobe-11+norm", None, None, counts) == Method("lobe", 11, normalize=True)
    assert resolve_cli_method("lobe-11+ring", None, None, counts) == Method("lobe", 11, True, pattern="ring")
    assert resolve_cli_method("lobe-11", False, None, counts) == Method("lobe", 11)  # +fit needs +norm
    assert resolve_cli_method("fis-11", None, None, counts) == Method("fis", 11)
    with pytest.raises(MethodError, match="--no-lobe-fit"):
        resolve_cli_method("lobe-11+norm+fit", None, False, counts)
    with pytest.raises(MethodError, match="N = 3, 7, 11 only"):
        resolve_cli_method("lobe-9+norm+fit", None, None, counts)
    # The parser's defaults and the shipped tables: `lobeview shot` renders lobe-11+norm+fit.
    from lobeview.app.cli import build_parser
    from lobeview.materials.fitted_pattern import fitted_sample_counts

    assert 11 in fitted_sample_counts()
    assert _resolve_args(build_parser().parse_args(["shot", "--out=x.png"])) == fitted
    no_fit = build_parser().parse_args(["shot", "--out=x.png", "--no-lobe-fit"])
    assert _resolve_args(no_fit) == Method("lobe", 11, normalize=True)


def test_command_line_normalisation_rule_and_its_inverse():
    # --lobe-normalize is on by default; lobe-N+norm says it explicitly; a contradiction is refused.
    assert resolve_cli_method("lobe-11", True, False) == Method("lobe", 11, normalize=True)
    assert resolve_cli_method("lobe-11", False) == Method("lobe", 11)
    assert resolve_cli_method("lobe-11+norm", True) == Method("lobe", 11, normalize=True)
    assert resolve_cli_method("fis-16", False) == Method("fis", 16)
    with pytest.raises(MethodError):
        resolve_cli_method("lobe-11+norm", False)
    # Eq. 4.24 is never normalised, whatever the flag.
    for flag in (None, True, False):
        assert resolve_cli_method("lobe-15+eq4.24", flag) == Method("lobe", 15, weighting="eq4.24")
    from lobeview.app.cli import build_parser

    for method in _all_methods():
        argv = ["shot", "--out=x.png", *shlex.split(method_cli_flags(method))]
        args = build_parser().parse_args(argv)
        assert _resolve_args(args) == method


def test_panel_choices_keep_the_normalisation_for_global_and_per_object_methods():
    for choice in realtime_choices():
        method = method_from_choice(choice, 9, normalize=True)
        assert method_choice(method) == choice
        assert method.normalize == (choice == "lobe")
        assert Method.parse(str(method)) == method
    assert method_from_choice("lobe", 500, True) == Method("lobe", MAX_PATTERN, normalize=True)


def test_shot_command_pastes_back_to_the_same_view(tmp_path):
    """The command F12 prints, with a camera whose vectors start with '-' (argparse took
    '--up -0.01,...' for an option), quoted paths and every scene option, parses with the real
    parser into the same camera, size, method and files."""
    import argparse

    from lobeview.app.cli import build_parser
    from lobeview.app.options import camera_from_args, lobeview_program, shot_command
    from lobeview.core.errors import parse_size
    from lobeview.viewer.camera import Camera

    camera = Camera((-1.25, 0.5, -3.0), (-0.1, -0.2, 0.3), (-0.0153786, 0.98, -0.18), 37.5)
    options = argparse.Namespace(env="my env.exr", face_size=64, reflection_proxy="room", mirrors=False,
                                 mirror_scale=0.5, cache=str(tmp_path / "a cache"), mip_filter="box",
                                 shared_probes=True)  # fmt: skip
    for method, spp in ((Method("lobe", 11, normalize=True), None), (Method("lobe", 5), None),
                        (Method.parse("reference"), 188), (Method.parse("prefiltered-lobe"), None)):  # fmt: skip
        line = shot_command(camera, (320, 200), method, tmp_path / "out dir" / "s.png", scene="my scene.glb",
                            spp=spp, args=options, materials=tmp_path / "m.json", exposure=-1.5)  # fmt: skip
        argv = shlex.split(line)
        start = argv.index("shot")
        assert argv[:start] == lobeview_program()  # pastes anywhere: no reliance on PATH (issue 41)
        args = build_parser().parse_args(argv[start:])
        assert args.scene == "my scene.glb" and args.out == str(tmp_path / "out dir" / "s.png")
        assert _resolve_args(args) == method
        assert parse_size(args.size) == (320, 200) and (args.spp == spp if spp else True)
        assert (args.env, args.face_size, args.reflection_proxy, args.mirrors, args.mirror_scale, args.cache) == (
            "my env.exr", 64, "room", False, 0.5, str(tmp_path / "a cache"))  # fmt: skip
        assert args.materials == str(tmp_path / "m.json") and args.exposure == -1.5 and args.mip_filter == "box"
        assert args.shared_probes
        pasted = camera_from_args(args, ((9, 9, 9), (0, 0, 0), (0, 1, 0), 90.0))  # every value overridden
        for name in ("position", "target", "up"):
            assert getattr(pasted, name) == pytest.approx(getattr(camera, name), abs=1e-8)
        assert pasted.fov_y == pytest.approx(camera.fov_y)


def test_bounded_cache_keeps_the_most_recently_used_entries():
    released = []
    cache = BoundedCache(2, on_evict=released.append)
    assert cache.get("a", lambda: 1) == 1 and cache.get("b", lambda: 2) == 2
    assert cache.get("a", lambda: 99) == 1  # a hit: 'a' becomes the most recent
    cache.get("c", lambda: 3)
    assert released == [2] and "a" in cache and "b" not in cache and len(cache) == 2
    cache.clear()
    assert sorted(released) == [1, 2, 3] and len(cache) == 0
    with pytest.raises(ValueError):
        BoundedCache(0)


# -- the import graph ------------------------------------------------------------------------------
def _module_name(path: Path) -> str:
    parts = path.relative_to(REPO).with_suffix("").parts
    parts = parts[:-1] if parts[-1] == "__init__" else parts
    return ".".join(("lobeview", *parts))


def _imports(path: Path) -> list[tuple[str, bool]]:
    """(imported lobeview module, at module level?) for every import in the file: absolute
    ``lobeview.*`` and relative ones (resolved against the package-dir mapping)."""
    module = _module_name(path)
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    tree = ast.parse(path.read_text())
    top_level = {id(node) for node in tree.body}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                prefix = ".".join(base + ([node.module] if node.module else []))
            else:
                prefix = node.module or ""
            names = [prefix] + [f"{prefix}.{alias.name}" for alias in node.names]
        else:
            continue
        for name in names:
            if name == "lobeview" or name.startswith("lobeview."):
                found.append((name, id(node) in top_level))
    return found


def _graph():
    files = {_module_name(p): p for pkg in PACKAGES for p in (REPO / pkg).glob("*.py")}
    edges = {}
    for module, path in files.items():
        targets = set()
        for name, top in _imports(path):
            while name not in files and "." in name:  # 'lobeview.core.methods.Method' -> the module
                name = name.rsplit(".", 1)[0]
            if name in files and name != module:
                targets.add((name, top))
        edges[module] = targets
    return files, edges


def test_layers_point_one_way_and_core_imports_nothing_of_lobeview():
    """docs/architecture.md: app -> viewer -> materials/scenes -> core, and the benchmarks beside the app
    (``lobeview bench`` runs them; they never import the app: issue 38). Checked over the AST
    (the package-dir mapping hides lobeview.* imports from ordinary tools), lazy imports included."""
    allowed = {
        "core": {"core"},
        "materials": {"core", "materials"},
        "scenes": {"core", "materials", "scenes"},
        "viewer": {"core", "materials", "scenes", "viewer", "shaders"},
        "app": {"core", "materials", "scenes", "viewer", "app", "shaders", "bench"},
        "bench": {"core", "materials", "scenes", "viewer", "shaders", "bench"},
    }
    files, edges = _graph()
    assert len(files) > 60
    wrong = []
    for module, targets in edges.items():
        layer = module.split(".")[1]
        for target, _ in targets:
            if target.split(".")[1] not in allowed[layer]:
                wrong.append(f"{module} -> {target}")
    assert not wrong, wrong


def test_no_circular_imports_lazy_ones_included():
    """No module reaches itself through imports, at module level or inside a function (a lazy
    import that closes a circle hides a layering knot, issue 38)."""
    files, edges = _graph()
    graph = {m: {t for t, _ in targets} for m, targets in edges.items()}
    state, stack, cycles = {}, [], []

    def visit(node):
        state[node] = "open"
        stack.append(node)
        for nxt in graph.get(node, ()):
            if state.get(nxt) == "open":
                cycles.append(stack[stack.index(nxt) :] + [nxt])
            elif nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = "done"

    for node in sorted(graph):
        if node not in state:
            visit(node)
    assert not cycles, cycles
    # The graph really sees the package-dir mapping: a known edge is there.
    assert "lobeview.core.methods" in graph["lobeview.viewer.render_base"]


def test_no_file_over_700_lines_and_no_class_over_30_methods():
    """issue 38: a file or class past these sizes holds more than one concern (the renderer was
    1014 lines with 52 methods); split it before adding to it."""
    too_long, too_wide = [], []
    for path in sorted(REPO.rglob("*.py")):
        if ".venv" in path.parts or "build" in path.parts:
            continue
        text = path.read_text()
        if text.count("\n") > 700:
            too_long.append(f"{path.relative_to(REPO)}: {text.count(chr(10))} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.ClassDef):
                methods = sum(isinstance(b, ast.FunctionDef | ast.AsyncFunctionDef) for b in node.body)
                if methods > 30:
                    too_wide.append(f"{path.relative_to(REPO)}: {node.name} has {methods} methods")
    assert not too_long and not too_wide, too_long + too_wide
