"""The package's layout stays as docs/architecture.md says: import arrows point down, no module imports itself
round a circle, torch stays in train/, no module outgrows what a reader holds in mind, and the tests mirror the
package. Imports are read with ast (nothing is imported), including those inside functions, since the heavy ones
are deliberately lazy."""

from __future__ import annotations

import ast
import json
import re
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "diviewer"
MAX_LINES = 450

LAYERS = {
    # 0: leaves every floor may use
    "errors": 0, "paths": 0, "provenance": 0, "console": 0, "timing": 0, "imageio": 0, "metrics": 0, "outputs": 0,
    "locks": 0, "faults": 0, "exposure": 0, "fieldspec": 0,
    # 1: scene data and math; the model contract (the channel encoding, padding, conditioning, the ONNX run)
    "scene/": 1, "contract/": 1,
    # 2: what draws a frame: GL passes, the path tracer, frame records
    "gl/": 2, "reference/": 2, "frames": 2,
    # 3: datasets and single renders
    "data/": 3, "render": 3, "render_path": 3, "headless": 3,
    # 4: training and evaluation
    "train/": 4, "evaluation/": 4,
    # 5: the applications
    "viewer/": 5, "bench/": 5, "builder/": 5, "ship/": 5,
    # 6: the command line
    "cli": 6, "commands/": 6, "options": 6, "__main__": 6,
}
"""Each unit (a subpackage, or a top-level module) and its floor: a unit imports only its own floor or lower."""

ENTRY_POINTS = {"diviewer.train.cli": "diviewer.commands.train"}
"""Modules that only give a command a documented ``python -m`` name (torchrun's `-m diviewer.train.cli`), and the
command module each runs: the one import allowed to point up."""


def _unit(module: str) -> str:
    """``diviewer.gl.neural`` -> ``gl/``; ``diviewer.contract.runtime`` -> ``runtime``."""
    parts = module.split(".")
    if len(parts) < 2:
        return parts[0]
    return f"{parts[1]}/" if (PACKAGE / parts[1]).is_dir() else parts[1]


def _modules(package: Path = PACKAGE) -> list[tuple[Path, str]]:
    out = []
    for path in sorted(package.rglob("*.py")):
        parts = path.relative_to(package.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out.append((path, ".".join(parts)))
    return out


def _is_module(name: str, package: Path) -> bool:
    """Whether ``name`` (``diviewer.gl.neural``) is a module or subpackage of ``package``."""
    rel = Path(*name.split(".")[1:]) if "." in name else Path()
    return (package / rel).with_suffix(".py").is_file() or (package / rel / "__init__.py").is_file()


def _imports(path: Path, module: str, package: Path = PACKAGE) -> set[str]:
    """Every module ``path`` imports, anywhere in it (lazy imports too), relative imports resolved; ``from
    diviewer import gl`` and ``from . import sources`` import the submodule (not the package's own code)."""
    names = set()
    pkg = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(pkg[: len(pkg) - node.level + 1] + ([base] if base else []))
            subs = {f"{base}.{a.name}" for a in node.names if base.split(".")[0] == package.name
                    and _is_module(f"{base}.{a.name}", package)}
            names.update(subs)
            if len(subs) < len(node.names):  # a name defined in base itself: base's code runs for it
                names.add(base)
    return names


GRAPH = {module: (_unit(module), path, _imports(path, module)) for path, module in _modules()}


def _offenders(source_units, forbidden) -> list[str]:
    """``module imports name`` for each module of ``source_units`` importing something ``forbidden`` accepts."""
    return sorted(f"{m} imports {name}" for m, (unit, _, names) in GRAPH.items()
                  if unit in source_units for name in names if forbidden(name))


def _is_unit(*units):
    return lambda name: name.startswith("diviewer.") and _unit(name) in units


def _is_root(*roots):
    return lambda name: name.split(".")[0] in roots


def test_the_graph_was_read(tmp_path):
    """The rules below judge something: every unit is placed, and imports (lazy, relative) are found."""
    units = {unit for unit, _, _ in GRAPH.values()} - {"diviewer"}
    assert units == set(LAYERS), f"place new units on a floor in LAYERS: {sorted(units ^ set(LAYERS))}"
    assert "diviewer.gl.display" in GRAPH["diviewer.viewer.app"][2]
    assert "torch" in GRAPH["diviewer.train.networks"][2]
    probe = tmp_path / "probe.py"
    probe.write_text("import os\nfrom . import sources\ndef f():\n    from ..gl.neural import NeuralPass\n"
                     "    import torch.nn\n")
    assert _imports(probe, "diviewer.viewer.probe") == {"os", "diviewer.viewer.sources", "diviewer.gl.neural",
                                                        "torch.nn"}


def test_no_import_points_upward():
    upward = sorted(f"{m} ({unit}, floor {LAYERS[unit]}) imports {name} ({_unit(name)}, floor {LAYERS[_unit(name)]})"
                    for m, (unit, _, names) in GRAPH.items() if unit in LAYERS
                    for name in names if name.startswith("diviewer.") and _unit(name) in LAYERS
                    and LAYERS[_unit(name)] > LAYERS[unit] and ENTRY_POINTS.get(m) != name)
    assert not upward, "\n".join(upward)
    for entry, command in ENTRY_POINTS.items():  # an entry point is that import and nothing else
        assert GRAPH[entry][2] == {command, "sys"}, GRAPH[entry][2]


def test_only_the_command_line_imports_the_commands():
    assert not _offenders(set(LAYERS) - {"commands/", "cli", "__main__", "options"},
                          lambda name: name.startswith("diviewer.commands") and name not in ENTRY_POINTS.values())


ARGPARSE_PRIVATES = re.compile(r"\._actions\b|_SubParsersAction|_option_string_actions|\._get_[a-z_]+\(|"
                               r"\._subparsers\b|\._group_actions\b|\._HelpAction|\._VersionAction")
"""argparse's internals: a command finds its chosen subparser and its options through what it recorded
(`diviewer.commands.common`), never through these."""


def test_no_argparse_privates():
    uses = [f"{path.relative_to(PACKAGE.parent)}:{n}: {line.strip()}" for path in sorted(PACKAGE.rglob("*.py"))
            for n, line in enumerate(path.read_text().splitlines(), 1) if ARGPARSE_PRIVATES.search(line)]
    assert not uses, "\n".join(uses)
    assert ARGPARSE_PRIVATES.search("for a in parser._actions:") and ARGPARSE_PRIVATES.search("argparse._SubParsersAction")
    assert ARGPARSE_PRIVATES.search("p._get_formatter()") and not ARGPARSE_PRIVATES.search("p.add_argument('--x')")


def test_scene_imports_no_gl_no_torch_no_viewer():
    assert not _offenders({"scene/"}, _is_unit("gl/", "viewer/")), "scene/ is data and math"
    assert not _offenders({"scene/"}, _is_root("torch", "moderngl", "glfw", "imgui_bundle"))


def test_gl_imports_no_torch_and_no_viewer():
    assert not _offenders({"gl/"}, _is_unit("viewer/"))
    assert not _offenders({"gl/"}, _is_root("torch"))


def test_only_train_imports_torch():
    assert not _offenders(set(LAYERS) - {"train/"}, _is_root("torch", "torchvision"))


def test_viewer_bench_and_runtime_never_import_train():
    assert not _offenders({"viewer/", "bench/", "contract/"}, _is_unit("train/"))


LONG_MODULES: dict[str, str] = {}
"""Modules over `MAX_LINES` lines, each with why its concern is one: the length is a smell to explain, not a wall
(a module split at the count rather than by concern leaves two halves sharing their privates)."""
MAX_FUNCTION_LINES = 80


@pytest.mark.parametrize("path", sorted(PACKAGE.rglob("*.py")), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_a_long_module_says_why(path):
    lines = len(path.read_text().splitlines())
    name = path.relative_to(PACKAGE).as_posix()
    assert lines < MAX_LINES or name in LONG_MODULES, (
        f"{name} has {lines} lines: split it by concern (docs/architecture.md), or say in LONG_MODULES why its "
        "concern is one")


def test_functions_stay_readable():
    long = [f"{p.relative_to(PACKAGE)}:{n.lineno} {n.name}: {n.end_lineno - n.lineno + 1} lines"
            for p in sorted(PACKAGE.rglob("*.py")) for n in ast.walk(ast.parse(p.read_text()))
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.end_lineno - n.lineno + 1 > MAX_FUNCTION_LINES]
    assert not long, "functions over 80 lines:\n" + "\n".join(long)


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One import cycle (``[a, b, a]``) per strongly connected group of modules (Tarjan), self-imports aside."""
    index, low, stack, on_stack, groups = {}, {}, [], set(), []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in graph or w == v:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.add(w)
                if w == v:
                    break
            if len(group) > 1:
                groups.append(group)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return [_cycle_through(min(g), g, graph) for g in groups]


def _cycle_through(start: str, group: set[str], graph: dict[str, set[str]]) -> list[str]:
    """The shortest path from ``start`` back to itself inside ``group`` (breadth first)."""
    came_from, frontier = {start: None}, [start]
    while frontier:
        nxt = []
        for v in frontier:
            for w in sorted(graph[v] & group):
                if w == start:
                    path = [v]
                    while came_from[path[-1]] is not None:
                        path.append(came_from[path[-1]])
                    return path[::-1] + [start]
                if w not in came_from:
                    came_from[w] = v
                    nxt.append(w)
        frontier = nxt
    raise AssertionError(f"{start} is in a cycle group but no cycle was found")


def _graph_of(package: Path) -> dict[str, set[str]]:
    return {module: _imports(path, module, package) for path, module in _modules(package)}


def test_no_import_circles_lazy_imports_included():
    circles = _circles(_graph_of(PACKAGE))
    assert not circles, "import circles (move the shared piece down into a module both import):\n" + "\n".join(
        " -> ".join(c) for c in circles)


def test_the_circle_detector_finds_a_planted_circle(tmp_path):
    """A top-level import one way and a lazy one back, three modules round, and a clean tree beside them."""
    pkg = tmp_path / "planted"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from planted.sub import b\n")
    (pkg / "sub" / "b.py").write_text("def f():\n    from ..c import g\n")
    (pkg / "c.py").write_text("from . import a\n")
    (pkg / "leaf.py").write_text("import os\nfrom planted import a\n")
    graph = _graph_of(pkg)
    assert _circles(graph) == [["planted.a", "planted.sub.b", "planted.c", "planted.a"]]
    (pkg / "c.py").write_text("import json\n")
    assert _circles(_graph_of(pkg)) == []


TESTS = Path(__file__).resolve().parent
SUITES = {"extremes"}
DOCS_TESTS = {"test_docs_commands.py", "test_docs_examples.py", "test_results_page.py"}
"""Tests of the docs, not of a module: the commands of the pages run (tests/test_docs_commands.py); the results page
is what its data gives (tests/test_results_page.py, of tools/make_results.py)."""
"""Folders of tests/ that are suites across the package (run alone with their mark), not mirrors of a package."""
WHOLE_TESTS = {"test_walks.py", "viewer/test_frame_walk.py"}
"""Tests of the package as a whole, not of one module: the frame and recipe walks through its modules (the viewer's
frame beside the viewer's tests, for their display fixture)."""


def test_tests_mirror_the_package():
    """tests/<package>/test_<module>.py tests diviewer/<package>/<module>.py; tests/test_<name>.py a top-level module
    (or a script of tools/); shared fixtures live in tests/conftest.py, helpers in tests/*.py without test_."""
    root = PACKAGE.parent
    strays = []
    for path in sorted(TESTS.rglob("test_*.py")):
        rel = path.relative_to(TESTS)
        if rel.parts[0] in SUITES or rel.as_posix() in DOCS_TESTS | WHOLE_TESTS or path == Path(__file__).resolve():
            continue
        module = path.stem[len("test_"):]
        folder = PACKAGE.joinpath(*rel.parts[:-1])
        tool = len(rel.parts) == 1 and (root / "tools" / f"{module}.py").is_file()
        if not ((folder / f"{module}.py").is_file() or tool):
            strays.append(f"tests/{rel.as_posix()}: no {folder.relative_to(root).as_posix()}/{module}.py")
    assert not strays, "move each test file beside the module it tests:\n" + "\n".join(strays)


ROOT = PACKAGE.parent
LINK = re.compile(r"\]\(([^)\s#]*)(#[^)\s]*)?\)")


def _slugs(markdown: str) -> set[str]:
    """The anchors GitHub gives a page's headings: lower case, punctuation dropped, spaces to hyphens; a heading
    seen before gets -1, -2, ..."""
    seen: dict[str, int] = {}
    out = set()
    for heading in re.findall(r"^#{1,6} (.*?)\s*#*$", re.sub(r"```.*?```", "", markdown, flags=re.S), re.M):
        slug = re.sub(r"[^\w\- ]", "", heading.lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return out


def test_relative_links_in_the_docs_reach_a_file_and_a_heading():
    """Every relative link in README.md, docs/, tools/ and assets/ names a file of the tree, and every #anchor into
    a Markdown page one of its headings (sections get renamed; their links must follow)."""
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted((ROOT / "tools").rglob("*.md")),
             *sorted((ROOT / "assets").rglob("*.md"))]
    broken = []
    for page in pages:
        text = page.read_text(encoding="utf-8")
        for m in LINK.finditer(re.sub(r"```.*?```", "", text, flags=re.S)):
            target, anchor = m.group(1), m.group(2)
            if re.match(r"[a-z]+:", target):  # http(s), mailto: not this tree's
                continue
            path = (page.parent / target).resolve() if target else page
            if not path.exists():
                broken.append(f"{page.relative_to(ROOT)}: {target} does not exist")
            elif anchor and path.suffix == ".md" and anchor[1:] not in _slugs(path.read_text(encoding="utf-8")):
                broken.append(f"{page.relative_to(ROOT)}: {target}{anchor} names no heading")
    assert not broken, "\n".join(broken)


def test_heading_slugs_follow_githubs_rule():
    assert _slugs("# The viewer's frame time (2026-11-23)\n## A `code` heading: two, words\n# Notes\n# Notes\n") == {
        "the-viewers-frame-time-2026-11-23", "a-code-heading-two-words", "notes", "notes-1"}


def test_every_shell_script_parses():
    """tools/*.sh, docs/examples/*.sh and .ci/run parse (`bash -n`): a syntax error in a branch a run does not take
    would otherwise surface only when a user's run reaches it."""
    import subprocess

    root = PACKAGE.parent
    scripts = [*sorted((root / "tools").rglob("*.sh")), *sorted((root / "docs").rglob("*.sh")), root / ".ci" / "run"]
    bad = {}
    for script in scripts:
        r = subprocess.run(["bash", "-n", str(script)], capture_output=True, text=True)
        if r.returncode:
            bad[str(script.relative_to(root))] = r.stderr.strip()
    assert len(scripts) > 3 and not bad, bad


def test_tools_holds_only_what_its_readme_lists():
    """tools/ keeps the scripts that rebuild shipped files and the README's set-up and test commands, each listed in
    tools/README.md's table (tools/experiments/ has its own README); a script added without its line fails here."""
    readme = (ROOT / "tools" / "README.md").read_text()
    listed = set(re.findall(r"^\| `([^`/]+)` \|", readme, flags=re.M))
    present = {p.name for p in (ROOT / "tools").iterdir() if p.is_file() and p.name != "README.md"}
    assert present, "tools/ is empty"
    assert present == listed, (f"in tools/ but not in tools/README.md: {sorted(present - listed)}; "
                               f"listed but absent: {sorted(listed - present)}")


TREE_BUDGET_BYTES = 35_000_000
"""The tracked tree's ceiling: the device machine carries the working tree with the built environment in 64 MiB, and
a shipped model that outgrows it (a wider K of the ladder) is caught here, not when a lease refuses the carry."""


def test_the_tracked_tree_fits_its_budget():
    import shutil
    import subprocess

    root = PACKAGE.parent
    if shutil.which("git") is None or not (root / ".git").exists():
        pytest.skip("not a git checkout: no tracked tree to size")
    names = subprocess.run(["git", "ls-files", "-z"], cwd=root, capture_output=True, check=True).stdout.split(b"\0")
    sizes = {n.decode(): (root / n.decode()).stat().st_size for n in names if n and (root / n.decode()).is_file()}
    total = sum(sizes.values())
    largest = sorted(sizes.items(), key=lambda kv: -kv[1])[:5]
    assert len(sizes) > 100 and total < TREE_BUDGET_BYTES, (
        f"tracked tree {total / 1e6:.2f} MB, budget {TREE_BUDGET_BYTES / 1e6:.0f} MB; largest: {largest}")


def test_the_data_the_docs_cite_is_laid_out_by_rows():
    """docs/data/ and the shipped sets' manifests: one line per record (`diviewer.outputs.dumps_rows`), a fifth
    smaller than one member a line, which is 2 MB of the tree's budget; each strict JSON (no NaN, no Infinity)."""
    from diviewer.outputs import dumps_rows

    def strict(name):
        raise ValueError(f"{name} is not strict JSON")

    root = PACKAGE.parent
    files = sorted(p for folder in ("docs/data", "assets/evalsets") for p in (root / folder).rglob("*.json"))
    assert files
    off = []
    for f in files:
        text = f.read_text(encoding="utf-8")
        if dumps_rows(json.loads(text, parse_constant=strict)) + ("\n" if text.endswith("\n") else "") != text:
            off.append(str(f.relative_to(root)))
    assert not off, f"not laid out by rows (diviewer.outputs.dumps_rows): {off}"


PRIVATE_ALLOWED: dict[tuple[str, str], str] = {}
"""(module, name) pairs that still reach into another module's underscore names, each with why."""


def _private_uses(path: Path, module: str, package: str = "diviewer") -> set[str]:
    """``other.module._name`` for each underscore name ``path`` takes from another module of ``package``: ``from
    other import _name``, or ``other._name`` on a module it imported (dunders aside)."""
    private = lambda name: name.startswith("_") and not name.startswith("__")
    pkg = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    tree = ast.parse(path.read_text(), str(path))
    found, aliases = set(), {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(pkg[: len(pkg) - node.level + 1] + ([base] if base else []))
            if base.split(".")[0] != package:
                continue
            for a in node.names:
                if private(a.name) and base != module:
                    found.add(f"{base}.{a.name}")
                aliases[a.asname or a.name] = f"{base}.{a.name}"
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == package:
                    aliases[a.asname or a.name] = a.name if a.asname else a.name.split(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and private(node.attr) and isinstance(node.value, ast.Name):
            target = aliases.get(node.value.id)
            if target and target != module:
                found.add(f"{target}.{node.attr}")
    return found


def test_no_module_takes_another_modules_underscore_names():
    """An underscore name is its module's own: a module that needs another's makes it public there first."""
    uses = {(m, name) for path, m in _modules() for name in _private_uses(path, m)}
    stale = set(PRIVATE_ALLOWED) - uses
    assert not stale, f"allowed uses that are gone (drop them from PRIVATE_ALLOWED): {sorted(stale)}"
    assert not uses - set(PRIVATE_ALLOWED), "\n".join(f"{m} takes {n}" for m, n in sorted(uses - set(PRIVATE_ALLOWED)))


def test_the_underscore_rule_finds_imports_and_attributes(tmp_path):
    probe = tmp_path / "probe.py"
    probe.write_text("from diviewer.scene import loader\nfrom diviewer.outputs import _a, dumps_rows\n"
                     "from . import _sibling\nimport diviewer.faults as faults\nimport os\n"
                     "def f():\n    return loader._camera, faults._x, os._exit, loader.__name__, _a\n")
    assert _private_uses(probe, "diviewer.viewer.probe") == {
        "diviewer.outputs._a", "diviewer.viewer._sibling", "diviewer.scene.loader._camera", "diviewer.faults._x"}


def test_no_test_imports_an_experiment():
    """tools/experiments/ holds measurements, not the product: a test checks the product (against an oracle of
    tests/oracles.py where it needs one), never a script of tools/experiments/."""
    offenders = sorted(str(p.relative_to(TESTS)) for p in TESTS.rglob("*.py") if p != Path(__file__).resolve()
                       and re.search(r"""load_tool\(\s*["']experiments/|tools[./]experiments[./]\w+ import""",
                                     p.read_text()))
    assert not offenders, offenders


README_MAX_LINES, README_MAX_LINE, DOCS_MAX_LINES, DOCS_MAX_DATED_HEADINGS = 150, 300, 2500, 3
"""The front page fits a screenful or three, the manual stays a manual: measured records live as JSON under docs/data
(docs/results.md is generated from it) and in git's history, not as dated sections of the pages."""
RECORD_WORDS = re.compile(r"\bissue \d+|\bsessions?\b|runs/`? lost|\blease[sd]?\b", re.I)
DATED_HEADING = re.compile(r"^#{1,6} .*\b\d{4}-\d{2}-\d{2}\b", re.M)


def _manual() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def test_the_readme_is_a_front_page():
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    longest = max(lines, key=len)
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines, at most {README_MAX_LINES}"
    assert len(longest) <= README_MAX_LINE, f"README.md's longest line is {len(longest)} characters: {longest[:80]}"


def test_the_manual_stays_short_and_undated():
    pages = sorted((ROOT / "docs").glob("*.md"))
    total = sum(len(p.read_text(encoding="utf-8").splitlines()) for p in pages)
    dated = [f"{p.relative_to(ROOT)}: {m.group(0)}" for p in pages
             for m in DATED_HEADING.finditer(re.sub(r"```.*?```", "", p.read_text(encoding="utf-8"), flags=re.S))]
    assert total <= DOCS_MAX_LINES, f"docs/*.md hold {total} lines, at most {DOCS_MAX_LINES}"
    assert len(dated) <= DOCS_MAX_DATED_HEADINGS, "dated headings:\n" + "\n".join(dated)


def test_the_manual_tells_no_records():
    """Pages state current behaviour: no issue numbers, no work sessions or machine loans, no lost folders."""
    found = [f"{p.relative_to(ROOT)}:{i}: {m.group(0)}" for p in _manual()
             for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) for m in RECORD_WORDS.finditer(line)]
    assert not found, "\n".join(found)


def test_the_record_checks_catch_what_they_look_for():
    assert RECORD_WORDS.findall("fixed in issue 26; the session of commit X; `runs/` lost; the lease ran out") == [
        "issue 26", "session", "runs/` lost", "lease"]
    assert not RECORD_WORDS.search("a released model; the issues a user can cause")
    assert DATED_HEADING.findall("## The frame (2026-11-24)\ntext 2026-11-24\n## Speed\n") == ["## The frame (2026-11-24"]


ASSET_RECORD_WORDS = re.compile(RECORD_WORDS.pattern + r"|\bissues?\b|\b[AH]100\b|\b\d{4}-\d{2}-\d{2}\b", re.I)
"""What a shipped recipe or scene file, which users copy, never says: the manual's record words, any issue, a
machine's name, a date."""
TREE_PATH = re.compile(r"(?<![\w:./-])(?:docs|tools|assets|diviewer)/[\w./-]*\w")
"""A path of this tree named in a file's text (``docs/build.md``); one inside a git revision
(``70db0ad:tools/x.sh``) names the past and is not looked for."""


def _asset_records(text: str) -> list[str]:
    """The record words of `ASSET_RECORD_WORDS` in ``text``, and each tree path it names that does not exist."""
    words = [m.group(0) for m in ASSET_RECORD_WORDS.finditer(text)]
    missing = [m.group(0) for m in TREE_PATH.finditer(text) if not (ROOT / m.group(0)).exists()]
    return words + [f"{p} does not exist" for p in missing]


SHIPPED_TOML = sorted((ROOT / "assets").glob("recipes/*.toml")) + sorted((ROOT / "assets").glob("scenes/*.toml"))


@pytest.mark.parametrize("path", SHIPPED_TOML, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_the_shipped_recipes_and_scenes_tell_no_records(path):
    """A shipped recipe or scene file says what it builds and why, for a user who copies it: no dates, issues,
    sessions or machines, and every docs/, tools/, assets/ or diviewer/ path it names is in the tree."""
    lines = path.read_text(encoding="utf-8").splitlines()
    found = [f"{path.relative_to(ROOT)}:{i}: {r}" for i, line in enumerate(lines, 1) for r in _asset_records(line)]
    assert not found, "\n".join(found)


def test_the_asset_record_check_catches_what_it_looks_for():
    assert _asset_records("trained on the H100 lease of 2026-11-23 (issue 25; docs/sponza.md, docs/build.md)") == [
        "H100", "lease", "2026-11-23", "issue 25", "docs/sponza.md does not exist"]
    assert _asset_records("the script: `git show 70db0ad:tools/sponza_chain.sh`; tools/make_atrium.py") == []
    assert _asset_records("(docs/data/sponza256_ladder/, assets/models/sponza_ladder.json)") == []
