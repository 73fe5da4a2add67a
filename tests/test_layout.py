"""The package's shape: no import cycle among mitsuba_lab's modules, every module imports,
the command line's layer imports no Mitsuba / Dr.Jit / numpy, and modules stay short."""
import ast
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: Where each part of the installed package lives in the checkout (pyproject's package-dir).
SOURCES = {"mitsuba_lab": os.path.join(ROOT, "src", "mitsuba_lab"),
           "mitsuba_lab.plugins": os.path.join(ROOT, "plugins")}
MAX_LINES = 500


def module_files() -> dict[str, str]:
    """Module name -> file, for every .py file of the package (plugins included)."""
    found = {}
    for package, folder in SOURCES.items():
        for here, dirs, files in os.walk(folder):
            dirs[:] = [d for d in dirs if d != "__pycache__"]
            rel = os.path.relpath(here, folder)
            parts = [package] + ([] if rel == "." else rel.split(os.sep))
            for name in files:
                if name.endswith(".py"):
                    stem = name[:-3]
                    found[".".join(parts if stem == "__init__" else parts + [stem])] = os.path.join(here, name)
    return found


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or \
        (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _import_nodes(tree: ast.Module, deferred: bool):
    """The import statements that run when the module is imported (everything but function
    bodies and ``if TYPE_CHECKING:`` blocks), and with ``deferred`` those in functions too."""
    stack = list(tree.body)
    while stack:
        node = stack.pop()
        if not deferred and isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            continue
        if isinstance(node, ast.If) and _is_type_checking(node):
            stack.extend(node.orelse)
            continue
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        stack.extend(ast.iter_child_nodes(node))


def _known(name: str, modules) -> str | None:
    """``name`` or its longest prefix that is one of ``modules``."""
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def import_graph(modules: dict[str, str], deferred: bool = False) -> dict[str, set[str]]:
    """Module -> the package modules it imports at import time (``deferred``: or in a function).
    ``cli`` imports each command module by name when its verb is used: those edges are added."""
    graph = {}
    for name, path in modules.items():
        with open(path, encoding="utf-8") as handle:
            tree = ast.parse(handle.read(), path)
        package = name if path.endswith("__init__.py") else name.rpartition(".")[0]
        edges = set()
        for node in _import_nodes(tree, deferred):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            else:
                if node.level:
                    base = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                    target = f"{base}.{node.module}" if node.module else base
                else:
                    target = node.module or ""
                targets = [f"{target}.{alias.name}" for alias in node.names] + [target]
                targets = [t for t in targets if t in modules] or [target]
            edges.update(filter(None, (_known(t, modules) for t in targets
                                       if t.split(".")[0] == "mitsuba_lab")))
        edges.discard(name)
        graph[name] = edges
    from mitsuba_lab import cli

    for module, _ in cli.COMMANDS.values():
        graph["mitsuba_lab.cli"].add(f"mitsuba_lab.{module}")
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, on_stack, stack, found = {}, {}, set(), [], []

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in graph.get(node, ()):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                top = stack.pop()
                on_stack.discard(top)
                component.append(top)
                if top == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def test_the_scan_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycle():
    from mitsuba_lab import cli

    graph = import_graph(module_files())
    commands = {f"mitsuba_lab.{module}" for module, _ in cli.COMMANDS.values()}
    assert graph["mitsuba_lab.cli"] == {"mitsuba_lab.commands.args"} | commands
    assert set(graph) >= set().union(*graph.values())          # every edge names a module
    assert cycles(graph) == []


def test_the_plugins_import_nothing_of_the_orchestration_layer():
    """plugins/ stands on its own (scene traits, parameter declarations, variant checks and the
    Ctrl-C handling it needs live in it): the orchestration layer imports the plugins, never the
    reverse, not even inside a function."""
    graph = import_graph(module_files(), deferred=True)
    reaching_out = {name: sorted(t for t in targets if not t.startswith("mitsuba_lab.plugins"))
                    for name, targets in graph.items() if name.startswith("mitsuba_lab.plugins")}
    assert {name: targets for name, targets in reaching_out.items() if targets} == {}


def test_no_import_cycle_counting_imports_inside_functions():
    """Deferred imports too: the library never reaches back into cli."""
    graph = import_graph(module_files(), deferred=True)
    assert not [m for m, edges in graph.items() if "mitsuba_lab.cli" in edges and m != "mitsuba_lab.__main__"]
    assert cycles(graph) == []


def test_every_module_imports_in_a_fresh_interpreter():
    names = sorted(n for n in module_files() if not n.endswith("__main__"))
    code = ("import importlib, sys\n"
            "import mitsuba_lab\n"
            f"for name in {names!r}:\n"
            "    importlib.import_module(name)\n"
            "print('ok')\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", "\n".join(proc.stderr.strip().splitlines()[-3:])


def test_the_command_line_layer_imports_no_mitsuba():
    """cli and each command module, each first in a fresh interpreter as the command starts it:
    they import, and none pulls in Mitsuba, Dr.Jit or numpy (``--help`` stays fast)."""
    names = ["mitsuba_lab.cli"] + sorted(n for n in module_files() if n.startswith("mitsuba_lab.commands."))
    code = ("import importlib, os, sys\n"
            "os.environ['MITSUBA_LAB_ACTIVATE'] = '0'\n"   # as the mitsuba-lab command imports it
            "importlib.import_module(sys.argv[1])\n"
            "print(sorted(m for m in ('mitsuba', 'drjit', 'numpy') if m in sys.modules))\n")
    for name in names:
        proc = subprocess.run([sys.executable, "-c", code, name], capture_output=True, text=True,
                              timeout=120, cwd=ROOT)
        assert proc.returncode == 0, f"{name}: {proc.stderr[-2000:]}"
        assert proc.stdout.strip() == "[]", f"{name} imports {proc.stdout.strip()}"


#: The library: it parses no arguments and prints nothing (commands/ owns the terminal).
LIBRARY = ("mitsuba_lab.experiment", "mitsuba_lab.check", "mitsuba_lab.inverse")


def _in_library(name: str) -> bool:
    return any(name == top or name.startswith(top + ".") for top in LIBRARY)


def test_the_library_imports_nothing_of_the_command_line():
    """experiment/, check/ and inverse/ import neither cli nor commands/, not even inside a
    function: what a command prints and parses lives in its module of commands/."""
    graph = import_graph(module_files(), deferred=True)
    reaching = {name: sorted(t for t in targets if t == "mitsuba_lab.cli" or t.startswith("mitsuba_lab.commands"))
                for name, targets in graph.items() if _in_library(name)}
    assert {name: targets for name, targets in reaching.items() if targets} == {}


def _prints(tree: ast.Module) -> list[int]:
    """Lines of print() calls, those of an ``if __name__ == "__main__":`` block (a module run
    as a script) left out."""
    def is_main(node):
        return isinstance(node, ast.If) and isinstance(node.test, ast.Compare) and \
            isinstance(node.test.left, ast.Name) and node.test.left.id == "__name__"
    stack, found = [n for n in tree.body if not is_main(n)], []
    while stack:
        node = stack.pop()
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "print":
            found.append(node.lineno)
        stack.extend(ast.iter_child_nodes(node))
    return sorted(found)


def test_the_scan_finds_a_print():
    assert _prints(ast.parse("def f():\n    print('x')\nif __name__ == '__main__':\n    print('y')\n")) == [2]


def test_the_library_prints_nothing():
    """The sweep runner, check and invert report through return values and callbacks (progress, ``say``);
    the commands print. (A module's own ``__main__`` block, run as a script, may print.)"""
    printing = {}
    for name, path in module_files().items():
        if _in_library(name):
            with open(path, encoding="utf-8") as handle:
                lines = _prints(ast.parse(handle.read(), path))
            if lines:
                printing[name] = lines
    assert printing == {}


def test_the_report_sections_are_listed_once_and_completely():
    """Every module of experiment/report/sections/ is one entry of SECTIONS (the page's order) and
    has ``applies`` and ``render``; nothing else is listed."""
    from mitsuba_lab.experiment.report import sections

    folder = os.path.dirname(sections.__file__)
    modules = {name[:-3] for name in os.listdir(folder) if name.endswith(".py") and name != "__init__.py"}
    listed = [section.__name__.rpartition(".")[2] for section in sections.SECTIONS]
    assert sorted(listed) == sorted(modules) and len(set(listed)) == len(listed)
    assert all(callable(getattr(s, "applies", None)) and callable(getattr(s, "render", None))
               for s in sections.SECTIONS)


def _long_modules() -> dict[str, int]:
    """Module name -> line count, for every module over MAX_LINES."""
    long = {}
    for name, path in module_files().items():
        with open(path, encoding="utf-8") as handle:
            count = sum(1 for _ in handle)
        if count > MAX_LINES:
            long[name] = count
    return long


def test_no_module_over_500_lines():
    assert _long_modules() == {}


def test_every_package_is_listed_in_pyproject():
    """setuptools installs only the packages pyproject.toml lists: a new subpackage that is
    not listed works in the editable checkout and is missing from a wheel."""
    import tomllib

    with open(os.path.join(ROOT, "pyproject.toml"), "rb") as f:
        listed = set(tomllib.load(f)["tool"]["setuptools"]["packages"])
    found = set()
    for top, package in ((os.path.join(ROOT, "src", "mitsuba_lab"), "mitsuba_lab"),
                         (os.path.join(ROOT, "plugins"), "mitsuba_lab.plugins")):
        for folder, dirs, files in os.walk(top):
            dirs[:] = [d for d in dirs if d != "__pycache__"]
            if "__init__.py" in files:
                rel = os.path.relpath(folder, top)
                found.add(package if rel == "." else package + "." + rel.replace(os.sep, "."))
    assert found == listed


def test_the_integrator_families_share_only_common():
    """photon/, bdpt/ and the path family (path, naive, nee, mis) use what they share from
    integrators/common/, never each other's modules; vcm/ builds on bdpt/ as a whole."""
    base = "mitsuba_lab.plugins.integrators."
    families = {"path": {base + m for m in ("path", "naive", "nee", "mis")}}
    for name in module_files():
        for family in ("photon", "bdpt", "vcm"):
            if name.startswith(base + family + ".") or name == base + family:
                families.setdefault(family, set()).add(name)
    allowed = {"vcm": {"bdpt"}}
    graph = import_graph(module_files(), deferred=True)
    crossing = {}
    for family, members in families.items():
        for name in members:
            others = {target for other, theirs in families.items()
                      if other != family and other not in allowed.get(family, ())
                      for target in graph[name] & theirs}
            if others:
                crossing[name] = sorted(others)
    assert set(families) == {"path", "photon", "bdpt", "vcm"} and crossing == {}


def _scan_runtime(path: str) -> tuple[bool, bool]:
    """(imports mitsuba, registers plugins) of a module, from the statements that run when it
    is imported (``mi.register_integrator`` / ``mi.register_sampler`` outside functions)."""
    with open(path, encoding="utf-8") as handle:
        tree = ast.parse(handle.read(), path)
    mitsuba = any(name == "mitsuba" or name.startswith("mitsuba.")
                  for node in _import_nodes(tree, deferred=False)
                  for name in ([a.name for a in node.names] if isinstance(node, ast.Import)
                               else [node.module or ""] if not node.level else []))
    stack, registers = list(tree.body), False
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            continue
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr in ("register_integrator", "register_sampler")):
            registers = True
        stack.extend(ast.iter_child_nodes(node))
    return mitsuba, registers


def test_the_plugins_list_every_module_in_import_order():
    """plugins/__init__.py lists the package's modules by hand: every module once, each after
    the package modules it imports; the variant-free ones are those that import Mitsuba
    neither themselves nor through another module; the registering ones are those that call
    ``mi.register_*`` when imported."""
    from mitsuba_lab import plugins

    files = {name: path for name, path in module_files().items() if name.startswith("mitsuba_lab.plugins.")}
    assert len(plugins.MODULES) == len(set(plugins.MODULES)) and set(plugins.MODULES) == set(files)
    graph = import_graph(module_files())
    position = {name: i for i, name in enumerate(plugins.MODULES)}
    late = {name: sorted(t for t in graph[name] if t in position and position[t] > position[name])
            for name in plugins.MODULES}
    assert {name: targets for name, targets in late.items() if targets} == {}
    scanned = {name: _scan_runtime(path) for name, path in files.items()}
    bound = set()
    for name in plugins.MODULES:                       # dependencies first: one pass settles it
        if scanned[name][0] or graph[name] & bound:
            bound.add(name)
    assert plugins.VARIANT_FREE == set(files) - bound
    assert set(plugins.PLUGIN_MODULES) == {name for name in files if scanned[name][1]}
