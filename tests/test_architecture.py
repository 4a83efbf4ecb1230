"""ARCHITECTURE.md's layers: no module imports from a layer above its own."""

import ast
from pathlib import Path

import pytest

import cmosnoise

ROOT = Path(cmosnoise.__file__).parent

#: lowest first; a module may import its own layer and the layers below it
LAYERS = ["base", "config", "engine", "model", "io", "isp", "analysis", "app"]
BASE = {"errors", "_version", "inputs", "estimators", "colour_lib"}
FACADE = {"__init__", "__main__", "torch"}  # the package's public face: imports anything (torch: the optional extra)


def layer_of(module: str) -> str | None:
    """'cmosnoise.model.stages.prnu' -> 'model'; None for the facade (``cmosnoise``, ``cmosnoise.Sensor``)."""
    parts = module.split(".")
    if parts[0] != "cmosnoise":
        return "external"
    if len(parts) == 1:
        return None
    head = parts[1]
    if head in BASE:
        return "base"
    if head in LAYERS:
        return head
    return None  # the facade itself, or a name it exports


def module_name(path: Path) -> str:
    return ".".join(path.relative_to(ROOT.parent).with_suffix("").parts)


def imports_of(path: Path, module: str) -> list[tuple[int, str]]:
    """(line, absolute module) of every import in ``path`` (module ``module``), relative ones resolved."""
    package = module.rsplit(".", 1)[0] if path.name != "__init__.py" else module.removesuffix(".__init__")
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            if node.module is None:  # from . import a, b: each name is a module
                out += [(node.lineno, f"{target}.{a.name}") for a in node.names]
            else:
                out.append((node.lineno, target))
    return out


def sources():
    return sorted(p for p in ROOT.rglob("*.py") if p.stem not in FACADE or p.parent != ROOT)


def test_every_module_belongs_to_a_known_layer():
    for p in sources():
        mod = module_name(p)
        assert p.relative_to(ROOT).parts[0] in LAYERS or p.stem in BASE, f"{mod} is in no layer of ARCHITECTURE.md"
        assert layer_of(mod) in LAYERS, f"{mod} is in no layer of ARCHITECTURE.md"


def check_layers(path: Path, mod: str) -> None:
    own = LAYERS.index(layer_of(mod))
    for line, target in imports_of(path, mod):
        layer = layer_of(target)
        if layer == "external":
            continue
        assert layer is not None, f"{mod}:{line} imports the package facade ({target}); import the defining module"
        assert LAYERS.index(layer) <= own, f"{mod}:{line} ({LAYERS[own]}) imports {target} ({layer}), a layer above"


@pytest.mark.parametrize("path", sources(), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_import_from_a_layer_above(path):
    check_layers(path, module_name(path))


def test_the_checker_sees_an_upward_import(tmp_path):
    """The walk itself must catch a violation: a model module importing the app layer."""
    fake = tmp_path / "probe.py"
    fake.write_text("import numpy\nfrom ..config import Config\nfrom ..app import cli\n")
    with pytest.raises(AssertionError, match=r"probe:3 \(model\) imports cmosnoise.app \(app\), a layer above"):
        check_layers(fake, "cmosnoise.model.probe")
    fake.write_text("from .. import Sensor\n")
    with pytest.raises(AssertionError, match="facade"):
        check_layers(fake, "cmosnoise.model.probe")


def test_architecture_doc_names_every_layer_and_module():
    """ARCHITECTURE.md says where each piece lives: every layer's folder and every module's name appear in it."""
    doc = (Path(__file__).parents[1] / "ARCHITECTURE.md").read_text()
    for layer in LAYERS[1:]:
        assert f"{layer}/" in doc, layer
    src = Path(__file__).parents[1] / "src" / "cmosnoise"
    missing = sorted(str(p.relative_to(src)) for p in src.rglob("*.py")
                     if p.stem not in ("__init__", "__main__") and p.stem not in doc)
    assert not missing, f"modules ARCHITECTURE.md does not name: {missing}"


# ------------------------------------------------------------------ circles
def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """module -> the package's modules it imports (at any level: a function's import is an arrow too); a
    package's ``__init__`` is the package's own name, ``from .x import name`` points to ``x.name`` where that is
    a module."""
    mods = {}
    for p in root.rglob("*.py"):
        m = ".".join(p.relative_to(root.parent).with_suffix("").parts)
        mods[m.removesuffix(".__init__")] = p
    edges: dict[str, set[str]] = {m: set() for m in mods}
    for m, p in mods.items():
        package = m if p.name == "__init__.py" else m.rsplit(".", 1)[0]
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)] if node.level else []
                t = ".".join(base + ([node.module] if node.module else [])) if node.level else node.module
                targets = [f"{t}.{a.name}" if f"{t}.{a.name}" in mods else t for a in node.names]
            else:
                continue
            for t in targets:
                while t and t not in mods:
                    t = t.rpartition(".")[0]
                if t and t != m:
                    edges[m].add(t)
    return edges


def circles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The import circles: strongly connected groups of more than one module (Tarjan's algorithm, iterative)."""
    index, low, on, stack, out, count = {}, {}, set(), [], [], 0
    for start in edges:
        if start in index:
            continue
        work = [(start, iter(sorted(edges[start])))]
        index[start] = low[start] = count
        count += 1
        stack.append(start)
        on.add(start)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = count
                    count += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(edges.get(w, ())))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                group = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    group.append(w)
                    if w == v:
                        break
                if len(group) > 1:
                    out.append(sorted(group))
    return out


def test_no_import_circle_inside_a_layer_or_between_layers():
    """#58: a circle inside a layer (app/run <-> app/tiled, engine's kernel -> fixed_maps -> cuda_kernel <->
    cuda_device -> kernel) passed the layer test; any circle fails now."""
    found = circles(import_graph())
    assert not found, f"import circles: {found}"


def test_the_circle_check_sees_a_circle(tmp_path):
    pkg = tmp_path / "cmosnoise"
    (pkg / "app").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "app" / "__init__.py").write_text("")
    (pkg / "app" / "a.py").write_text("def f():\n    from . import b\n")
    (pkg / "app" / "b.py").write_text("from .c import g\n")
    (pkg / "app" / "c.py").write_text("from cmosnoise.app.a import f\n")
    assert circles(import_graph(pkg)) == [["cmosnoise.app.a", "cmosnoise.app.b", "cmosnoise.app.c"]]
    (pkg / "app" / "c.py").write_text("import numpy\n")
    assert circles(import_graph(pkg)) == []


def test_the_type_stub_names_what_the_lazy_init_exports():
    """#58: ``py.typed`` promises types, but ``__init__`` exports lazily (``__getattr__``), which type checkers
    cannot follow: ``__init__.pyi`` imports each public name from its module. It must say exactly what the
    tables say."""
    stub = ast.parse((ROOT / "__init__.pyi").read_text())
    found = {}
    for node in stub.body:
        if isinstance(node, ast.ImportFrom):
            for a in node.names:
                found[a.asname or a.name] = (("." * node.level) + (node.module or ""), a.name)
    want = {name: (f".{mod}", name) for name, mod in cmosnoise._NAMES.items()}
    want.update({name: (f".{mod.rpartition('.')[0]}", mod.rpartition(".")[2]) for name, mod in cmosnoise._MODULES.items()})
    want.update({"CmosnoiseError": (".errors", "CmosnoiseError"), "__version__": ("._version", "__version__"),
                 "errors": (".", "errors")})
    assert found == want
    assert set(cmosnoise.__all__) <= set(found)
