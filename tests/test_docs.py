"""The documentation cannot rot: every command line in the docs parses, every Python example runs, the docstrings'
examples run as doctests, and the README's test command is what CI runs.

The site itself is built by .ci/run with every warning an error (broken links, docstrings that do not parse, a
gallery example that fails).
"""

import doctest
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import cli

import cmosnoise

ROOT = Path(__file__).resolve().parent.parent
PACKAGE_ROOT = str(Path(cmosnoise.__file__).resolve().parent.parent)
SKIP = {"_build", "generated", "auto_examples"}


def pages() -> list[Path]:
    return [ROOT / "README.md", *sorted(p for p in (ROOT / "docs").rglob("*.md")
                                        if not SKIP & set(p.relative_to(ROOT).parts))]


def blocks(lang: str | None = None):
    """(page, text) of every fenced code block (of ``lang``, or without a language, if given)."""
    fence = re.compile(r"^```([A-Za-z]*)[^\n]*\n(.*?)^```", re.S | re.M)
    for page in pages():
        for m in fence.finditer(page.read_text()):
            if lang is None or m.group(1) == lang:
                yield page, m.group(2)


def command_lines():
    """Every ``cmosnoise ...`` line of the docs' code blocks: continuations joined, comments and redirections cut."""
    out = []
    for page, text in blocks():
        text = text.replace("\\\n", " ")
        for line in text.splitlines():
            line = line.strip().removeprefix("$ ")
            if not line.startswith("cmosnoise ") and "&& cmosnoise " not in line:
                continue
            line = line[line.index("cmosnoise "):]
            line = re.split(r"\s+#\s", line)[0]          # a comment
            line = re.split(r"\s[>|]\s", line)[0]        # a redirection or a pipe
            out.append((page.relative_to(ROOT).as_posix(), line))
    return out


COMMANDS = command_lines()


def test_the_docs_show_commands():
    assert len(COMMANDS) > 40 and {line.split()[1] for _, line in COMMANDS} >= {
        "simulate", "sweep", "compare", "fit", "measure", "characterize", "dataset", "evaluate", "explore"}


@pytest.mark.parametrize("page, line", COMMANDS, ids=[f"{p}:{i}" for i, (p, _) in enumerate(COMMANDS)])
def test_every_command_line_in_the_docs_parses(page, line):
    """Each documented command line is parsed by the command line itself (its options, their types, their
    ranges), without running it: a renamed option or a changed range fails here."""
    import typer.main

    from cmosnoise.app.cli import app

    group = typer.main.get_command(app)
    args = [a for a in shlex.split(line)[1:] if a != "..."]  # "..." elides options shown elsewhere
    while args and args[0].startswith("-"):  # the app's own options (-q, -v)
        args = args[1:]
    assert args, f"{page}: {line!r} names no command"
    cmd = group.commands.get(args[0])
    assert cmd is not None, f"{page}: {line!r}: no command {args[0]!r}"
    cmd.make_context(f"cmosnoise {args[0]}", args[1:])


def test_the_readme_commands_are_what_ci_runs():
    readme = (ROOT / "README.md").read_text()
    install, tests = [t.strip() for _, t in blocks() if _ == ROOT / "README.md"][:2]
    assert install.endswith("pip install . && cmosnoise simulate")
    assert "pip install -q '.[test]'" in tests and tests.endswith("python -m pytest -q")
    ci = (ROOT / ".ci" / "run").read_text().replace("\\\n", " ")
    ci = " ".join(ci.split())
    head = tests.partition(" && python -m pytest -q")[0]
    assert head in ci and ci.rstrip().endswith("python -m pytest -q"), "the README's test command is not .ci/run's"
    before = readme[:readme.index(tests)][-400:]  # the paragraph that introduces the test command states its time
    assert re.search(r"about \d+ minutes", before), before


def test_the_readme_training_data_commands_are_the_data_set_page_s():
    """The README's block for the image-processing engineer is the data-set page's, word for word (one text,
    shown in both places: each is where one reader looks first), and its picture is the page's."""
    def training(page):
        return [t for p, t in blocks() if p == page and "cmosnoise dataset" in t][0]

    page = ROOT / "docs" / "imaging" / "datasets.md"
    assert training(ROOT / "README.md") == training(page)
    assert "](docs/img/dataset_sample.png)" in (ROOT / "README.md").read_text()
    assert "](../img/dataset_sample.png)" in page.read_text()


PYTHON = [(page.relative_to(ROOT).as_posix(), text) for page, text in blocks("python")]


@pytest.mark.parametrize("page, code", PYTHON, ids=[f"{p}:{i}" for i, (p, _) in enumerate(PYTHON)])
@pytest.mark.slow
def test_every_python_example_in_the_docs_runs(page, code, tmp_path):
    """In a fresh interpreter, in an empty folder; a ``# cmosnoise ...`` comment in the example is the command
    that makes its input, run first. An example for the GPU runs where one is, and is compiled elsewhere."""
    for setup in re.findall(r"#\s*(cmosnoise [^\n]+)", code):
        r = cli(*shlex.split(setup)[1:], cwd=tmp_path)
        assert r.returncode == 0, f"{page}: {setup}: {r.stderr}"
    if '"cuda"' in code:
        import numba
        from numba import cuda

        if numba.config.ENABLE_CUDASIM or not cuda.is_available():  # the tests' CUDA simulator is no GPU
            compile(code, page, "exec")  # checked to compile here; it runs where a GPU is
            return
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"}  # a real device, where one is
    # the package these tests import (the checkout's src/ in a developer's editable install, the virtual
    # environment's copy in CI's): src/ always made a clean clone compile every loop a second time, numba's cache
    # being keyed by the source file's path (some 2 minutes of the suite, in the first example that ran)
    env["PYTHONPATH"] = PACKAGE_ROOT
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=600, env=env)
    assert r.returncode == 0, f"{page}:\n{code}\n{r.stderr[-3000:]}"


def _public_objects():
    for name in cmosnoise.__all__:
        if name == "__version__":
            continue
        obj = getattr(cmosnoise, name)
        yield name, obj


#: public names whose docstrings have no Examples section yet (this list only shrinks: a new name comes with one)
WITHOUT_EXAMPLES: set[str] = set()


@pytest.mark.slow
def test_the_docstrings_examples_run_as_doctests():
    """Every Examples section of the public names (and their members) runs, and gives what it shows; every public
    name but those listed has one."""
    missing = {name for name, obj in _public_objects() if ">>>" not in (obj.__doc__ or "")}
    assert missing <= WITHOUT_EXAMPLES, f"public names without an Examples section: {sorted(missing - WITHOUT_EXAMPLES)}"
    finder, runner = doctest.DocTestFinder(), doctest.DocTestRunner(optionflags=doctest.ELLIPSIS
                                                                    | doctest.NORMALIZE_WHITESPACE)
    ran = 0
    for name, obj in _public_objects():
        for test in finder.find(obj, f"cmosnoise.{name}", globs={"cmosnoise": cmosnoise}):
            if test.examples:
                result = runner.run(test, out=lambda s: None)
                assert result.failed == 0, f"the doctest of {test.name} fails"
                ran += result.attempted
    assert ran >= 100  # the examples exist (a finder that found none would pass silently)


@pytest.mark.slow
def test_the_sensor_guide_runs_as_written(tmp_path):
    """The guide's first study, as the page shows it: two runs that differ in the temperature, and compare."""
    guide = (ROOT / "docs" / "sensor" / "index.md").read_text()
    first = next(t for page, t in blocks() if page.name == "index.md" and page.parent.name == "sensor"
                 and "cmosnoise compare run25 run65" in t)
    assert first in guide and first.count("cmosnoise ") == 3
    for line in first.strip().splitlines():
        r = cli(*shlex.split(line)[1:], cwd=tmp_path)
        assert r.returncode == 0, f"{line}: {r.stderr}"
    assert (tmp_path / "cmp" / "compare.html").is_file() and (tmp_path / "run65" / "report.html").is_file()
    # #63: the first example shows the effect it is about, where the page points (the dark top-left corner):
    # the 65 C preview is brighter there by far more than the noise of one preview's 8-bit codes
    import imageio.v3 as iio

    a, b = (iio.imread(tmp_path / run / "preview.png")[:120, :160].astype(float) for run in ("run25", "run65"))
    assert b.mean() - a.mean() > 20 and (b - a).std() > 5, (a.mean(), b.mean(), (b - a).std())


#: every command's page (each example runs in a folder of its own, as a reader would run one page)
COMMAND_PAGES = ["presets", "config", "simulate", "process", "figures", "characterize", "quality", "compare", "sweep",
                 "measure", "fit", "dataset", "evaluate", "explore", "compile"]


@pytest.mark.slow
def test_every_commands_page_example_runs_as_written(tmp_path):
    """Each command's page shows an example, and it runs as written, in an empty folder (a page makes what it
    reads); explore, a server, is started, asked for its page and stopped by its id."""
    import urllib.request

    from conftest import free_port, stop_process

    pages = {p.stem for p in (ROOT / "docs" / "commands").glob("*.md")} - {"index"}
    assert pages == set(COMMAND_PAGES), "a command page is missing from the run order (or a command from the docs)"
    for name in COMMAND_PAGES:
        here = tmp_path / name
        here.mkdir()
        text = (ROOT / "docs" / "commands" / f"{name}.md").read_text()
        example = re.search(r"^```\n(.*?)^```", text, re.S | re.M).group(1).replace("\\\n", " ")
        for line in example.strip().splitlines():
            args = shlex.split(re.split(r"\s[>|]\s", line)[0])[1:]
            if args[0] == "explore":
                port = free_port()
                proc = subprocess.Popen([sys.executable, "-m", "cmosnoise", *args, "--no-browser", "--port", str(port)],
                                        cwd=here, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                try:
                    for _ in range(600):
                        try:
                            with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/meta", timeout=2) as r:
                                assert r.status == 200
                            break
                        except OSError:
                            assert proc.poll() is None, f"{name}: {line} ended"
                            import time

                            time.sleep(0.2)
                    else:
                        raise AssertionError(f"{name}: {line} did not serve its page")
                finally:
                    stop_process(proc)
                continue
            r = cli(*args, cwd=here)
            assert r.returncode == 0, f"docs/commands/{name}.md: {line}: {r.stderr[-2000:]}"
    for made in ("simulate/run1/raw.tiff", "simulate/tiled/raw.tiff", "process/pictures", "characterize/emva/characterization.json",
                 "quality/q/report.html",
                 "compare/cmp/compare.html", "sweep/yield/summary.csv", "measure/lab/manifest.yaml",
                 "fit/fitted/config.yaml", "dataset/data/dataset.json", "evaluate/scores", "figures/paper/index.html"):
        assert (tmp_path / made).exists(), made


def _numpydoc_gaps() -> dict[str, list[str]]:
    """Public functions, classes and the public methods of the classes (those of ``cmosnoise.__all__`` and of its
    modules) whose docstrings lack their Parameters or Returns sections, by numpydoc's own validation (PR01,
    PR02, RT01)."""
    import inspect

    from numpydoc.validate import validate

    names = []
    for _name, obj in _public_objects():
        if inspect.ismodule(obj):
            names += [f"{obj.__name__}.{k}" for k, v in vars(obj).items() if not k.startswith("_")
                      and (inspect.isfunction(v) or inspect.isclass(v)) and getattr(v, "__module__", "") == obj.__name__]
        elif inspect.isclass(obj) or inspect.isfunction(obj):
            names.append(f"{obj.__module__}.{obj.__qualname__}")
        if inspect.isclass(obj):  # and the public methods a class of the API defines (the sensor's, the spec's)
            names += [f"{obj.__module__}.{obj.__qualname__}.{k}" for k, v in vars(obj).items()
                      if not k.startswith("_") and inspect.isfunction(v)]
    gaps = {}
    for name in names:
        codes = sorted({c for c, _ in validate(name)["errors"]} & {"PR01", "PR02", "RT01"})
        if codes:
            gaps[name] = codes
    return gaps


def test_the_public_docstrings_have_numpydoc_parameters_and_returns():
    """Parameters (with shapes and units) and Returns for every public function and class, by numpydoc's own
    validation: a new public name comes with its sections."""
    gaps = _numpydoc_gaps()
    assert not gaps, f"public names without their Parameters or Returns sections: {gaps}"
