"""The hand-written parameter tables agree with the declarations (``plugins/params.py``), and
experiments/README.md lists every shipped config.

The tables live in ``plugins/design.md`` (how the plugins work; the generated reference,
``plugins/README.md``, is checked by ``tests/commands/test_plugins_command.py``).

Integrators: every row ``| `name` | type | default | meaning |`` of a parameter table has the
declared type and default of each lab integrator in its scope (the plugins named on the line
above the table, e.g. "`lab_mis` only:", else every lab integrator that declares the name), and
every parameter of a tabulated integrator is in a table. A plugin described in prose
("`lab_photon` ... Parameters: `name` (default), ...") names every declared parameter there,
and the defaults it states agree. Samplers: the shared "Parameters:" sentence and each
plugin's row of the sampler table together name every declared parameter, with the defaults
they state ("`name` (default X" or "`name` = X (default)") agreeing, and every allowed value
of a parameter with choices is named.
"""
import math
import os
import re

import pytest

from mitsuba_lab.commands.args import parse_value
from mitsuba_lab.plugins import params

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TYPES = {"int": int, "float": float, "bool": bool, "string": str}
INTEGRATORS = tuple(p for p in params.lab_plugins() if params.plugin_kind(p) == "integrator")
SAMPLERS = tuple(p for p in params.lab_plugins() if params.plugin_kind(p) == "sampler")


#: The file holding the integrator and sampler tables checked here.
TABLES = os.path.join("plugins", "design.md")


def section(title: str) -> str:
    with open(os.path.join(ROOT, TABLES), encoding="utf-8") as handle:
        text = handle.read()
    match = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text, re.M | re.S)
    assert match, f"{TABLES} has no '## {title}' section"
    return match.group(1)


def paragraphs(text: str) -> list[str]:
    return [p.strip() for p in re.split(r"\n\s*\n", text) if p.strip()]


def cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def parameter_tables(text: str) -> list[tuple[str, list[list[str]]]]:
    """(line above the table, rows) of every table whose header starts with parameter | type | default."""
    lines = text.splitlines()
    tables = []
    for i, line in enumerate(lines):
        if line.startswith("|") and cells(line)[:3] == ["parameter", "type", "default"]:
            above = next((lines[j] for j in range(i - 1, -1, -1) if lines[j].strip()), "")
            rows = []
            for row in lines[i + 2:]:
                if not row.startswith("|"):
                    break
                rows.append(cells(row))
            tables.append((above, rows))
    return tables


def readme_value(text: str):
    """A default as design.md writes it: `power`, false, 2/3, 2^21, -1, 0.5."""
    text = text.strip().strip("`").strip()
    if re.fullmatch(r"-?\d+/\d+", text):
        num, den = text.split("/")
        return int(num) / int(den)
    if re.fullmatch(r"\d+\^\d+", text):
        base, exp = text.split("^")
        return int(base) ** int(exp)
    return parse_value(text)             # true/false, ints, floats, strings: as on the command line


def agrees(stated, param) -> bool:
    if param.kind is bool or isinstance(stated, bool):
        return stated is param.default
    if param.kind is str:
        return stated == param.default
    return isinstance(stated, (int, float)) and math.isclose(stated, param.default, rel_tol=1e-12)


def declaration(plugin: str, name: str):
    return next((p for p in params.declared(plugin) if p.name == name), None)


def stated_defaults(text: str) -> list[tuple[str, str]]:
    """(name, default) pairs stated as "`name` (default X", "`name` = X (default)" or, after
    "Parameters:", as "`name` (X"."""
    found = re.findall(r"`(\w+)`\s+\(default\s+([^,)=;]+)", text)
    found += re.findall(r"`(\w+)`\s+=\s+(`?[\w.-]+`?)\s+\(default\)", text)
    return found


def prose_parameters(text: str, plugin: str) -> str | None:
    """The part after "Parameters:" of the paragraph that starts with `plugin`, if any."""
    for paragraph in paragraphs(text):
        if paragraph.startswith(f"`{plugin}`") and "Parameters:" in paragraph:
            return paragraph.split("Parameters:", 1)[1]
    return None


# -- Integrators --------------------------------------------------------------------------------

def test_the_integrator_tables_are_found():
    tables = parameter_tables(section("Integrators"))
    assert len(tables) >= 2
    assert {row[0].strip("`") for _, rows in tables for row in rows} >= {"max_depth", "heuristic"}


def test_integrator_table_rows_agree_with_the_declarations():
    checked = 0
    for above, rows in parameter_tables(section("Integrators")):
        named = [p for p in INTEGRATORS if f"`{p}`" in above]
        for row in rows:
            assert len(row) >= 4, row
            name, kind, default = row[0].strip("`"), row[1], row[2]
            assert kind in TYPES, f"{name}: unknown type '{kind}'"
            scope = named or [p for p in INTEGRATORS if declaration(p, name)]
            assert scope, f"design.md table row '{name}': no lab integrator declares it"
            for plugin in scope:
                param = declaration(plugin, name)
                assert param is not None, f"design.md says {plugin} has '{name}'; it does not declare it"
                assert param.kind is TYPES[kind], f"{plugin}.{name}: design.md type {kind}, declared {param.kind}"
                # (a shared row may name a plugin whose default differs: "`lab_mmlt`'s default 8")
                own = re.search(rf"`{plugin}`'s default `?([^`,;)\s]+)", row[3])
                stated = own.group(1) if own else default
                assert agrees(readme_value(stated), param), \
                    f"{plugin}.{name}: design.md default {stated}, declared {param.default!r}"
                for choice in param.choices:
                    assert f"`{choice}`" in row[3], f"{plugin}.{name}: design.md does not name '{choice}'"
                checked += 1
    assert checked >= 7


@pytest.mark.parametrize("plugin", INTEGRATORS)
def test_every_integrator_parameter_is_in_the_readme(plugin):
    text = section("Integrators")
    prose = prose_parameters(text, plugin)
    if prose is None:                       # described by the tables
        tables = parameter_tables(text)
        tabulated = {row[0].strip("`") for above, rows in tables for row in rows
                     if not any(f"`{p}`" in above for p in INTEGRATORS) or f"`{plugin}`" in above}
        missing = [p.name for p in params.declared(plugin) if p.name not in tabulated]
        assert not missing, f"design.md's integrator tables lack {plugin}'s {missing}"
        return
    missing = [p.name for p in params.declared(plugin) if f"`{p.name}`" not in prose]
    assert not missing, f"design.md's {plugin} paragraph does not name {missing}"
    stated = stated_defaults(prose) + re.findall(r"`(\w+)`\s+\(([^,)=;]+)", prose)
    assert stated
    for name, default in stated:
        param = declaration(plugin, name)
        assert param is not None, f"design.md names '{name}' as a {plugin} parameter"
        assert agrees(readme_value(default), param), \
            f"{plugin}.{name}: design.md default {default.strip()}, declared {param.default!r}"
    for param in params.declared(plugin):
        for choice in param.choices:
            assert f"`{choice}`" in prose, f"{plugin}.{param.name}: design.md does not name '{choice}'"


# -- Samplers -----------------------------------------------------------------------------------

def sampler_texts() -> tuple[str, dict[str, str]]:
    """(the shared "Parameters:" sentence, plugin -> its table row)."""
    text = section("Samplers")
    shared = next(p for p in paragraphs(text) if "Parameters:" in p).split("Parameters:", 1)[1]
    rows = {}
    for line in text.splitlines():
        if line.startswith("|") and cells(line)[0].strip("`") in SAMPLERS:
            rows[cells(line)[0].strip("`")] = line
    return shared, rows


def test_every_sampler_has_a_row():
    _, rows = sampler_texts()
    assert sorted(rows) == sorted(SAMPLERS)


@pytest.mark.parametrize("plugin", SAMPLERS)
def test_sampler_parameters_and_defaults_agree(plugin):
    shared, rows = sampler_texts()
    shared_names = {p.name for p in params.SAMPLER}
    row = rows[plugin]
    for param in params.declared(plugin):
        where = shared if param.name in shared_names else row
        assert f"`{param.name}`" in where, f"design.md does not name {plugin}'s '{param.name}'"
        for choice in param.choices:
            assert f"`{choice}`" in row, f"{plugin}.{param.name}: design.md does not name '{choice}'"
    stated = stated_defaults(shared) + stated_defaults(row)
    assert stated
    for name, default in stated:
        param = declaration(plugin, name)
        if param is None and name not in shared_names:
            pytest.fail(f"design.md names '{name}' as a {plugin} parameter; it does not declare it")
        if param is not None:
            assert agrees(readme_value(default), param), \
                f"{plugin}.{name}: design.md default {default.strip()}, declared {param.default!r}"


def test_readme_values_are_read_as_written():
    assert [readme_value(v) for v in ("-1", "false", "`power`", "2/3", "2^21", "0.5", " 16 ")] == \
        [-1, False, "power", 2 / 3, 2 ** 21, 0.5, 16]


# -- Shipped configs ----------------------------------------------------------------------------

def test_experiments_readme_lists_every_shipped_config():
    """Each experiments/*.toml has its row in experiments/README.md's table (| `name.toml` | ...),
    and every row names a file that exists."""
    folder = os.path.join(ROOT, "experiments")
    shipped = sorted(f for f in os.listdir(folder) if f.endswith(".toml"))
    assert len(shipped) >= 10
    with open(os.path.join(folder, "README.md"), encoding="utf-8") as handle:
        rows = [cells(line)[0].strip("`") for line in handle if line.startswith("| `") and ".toml`" in line]
    assert sorted(r for r in rows if r.endswith(".toml")) == shipped
