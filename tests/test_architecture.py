"""ARCHITECTURE.md's layers: no module imports from a layer above its own."""

import ast
from pathlib import Path

import pytest

import cmosnoise

ROOT = Path(cmosnoise.__file__).parent

#: lowest first; a module may import its own layer and the layers below it
LAYERS = ["base", "config", "engine", "model", "io", "isp", "analysis", "app"]
BASE = {"errors", "_version", "inputs", "estimators"}
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
