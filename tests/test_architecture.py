"""The package layout's rules, checked on the source: no import cycles inside ``renderer`` or ``service`` (imports
inside functions count too, so a cycle cannot hide there), dependencies pointing one way, ``pxr`` only in the USD
import package and the service's scene checks, the renderer importable with the service's libraries absent, the
client with its own extra alone, and the service's modules grouped by the process that runs them, importing each
other across groups only through the interfaces declared here."""
import ast
import fnmatch
import pathlib
import subprocess
import sys
import textwrap

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]


def module_name(path: pathlib.Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def imported_modules(path: pathlib.Path) -> set[str]:
    """Every module a file imports, anywhere in it (module level or inside functions), as absolute names."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module
            out.add(mod)
            out.update(f"{mod}.{a.name}" for a in node.names)  # "from pkg import module"
    return out


def graph(top: str) -> dict[str, set[str]]:
    files = {module_name(p): p for p in (ROOT / top).rglob("*.py")}
    return {m: {i for i in imported_modules(p) if i in files and i != m} for m, p in files.items()}


def cycles(g: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in g[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(10000)
    for v in g:
        if v not in index:
            visit(v)
    return out


def test_cycle_finder_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


@pytest.mark.parametrize("top", ["renderer", "service", "schemas"])
def test_no_import_cycles(top):
    assert cycles(graph(top)) == []


def test_dependencies_point_one_way():
    """renderer knows nothing of the service, the wire schemas, HTTP, the queue or Dask; schemas not the service."""
    service_libs = ("service", "schemas", "fastapi", "starlette", "pydantic", "sqlalchemy", "dask", "distributed",
                    "httpx", "uvicorn")
    for p in (ROOT / "renderer").rglob("*.py"):
        bad = [m for m in imported_modules(p) if m.split(".")[0] in service_libs]
        assert not bad, f"{p.relative_to(ROOT)} imports {bad}"
    for p in (ROOT / "schemas").rglob("*.py"):
        bad = [m for m in imported_modules(p) if m.split(".")[0] in ("service", "fastapi", "sqlalchemy", "dask")]
        assert not bad, f"{p.relative_to(ROOT)} imports {bad}"


def test_pxr_only_in_the_usd_package():
    allowed = {ROOT / "renderer" / "usd"}
    for p in (ROOT / "renderer").rglob("*.py"):
        if any(a in p.parents for a in allowed):
            continue
        pxr = [m for m in imported_modules(p) if m.split(".")[0] == "pxr"]
        assert not pxr, f"{p.relative_to(ROOT)} imports {pxr}: USD belongs in renderer/usd"


def run_without(blocked: set[str], code: str) -> subprocess.CompletedProcess:
    """Run ``code`` in a new interpreter in which importing any of the ``blocked`` packages fails."""
    prelude = textwrap.dedent(f"""
        import importlib.abc, sys
        class Block(importlib.abc.MetaPathFinder):
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] in {sorted(blocked)!r}:
                    raise ImportError(f"blocked: {{name}}")
        sys.meta_path.insert(0, Block())
    """)
    return subprocess.run([sys.executable, "-c", prelude + textwrap.dedent(code)], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)


def test_renderer_imports_and_parses_without_the_service_libraries():
    """A library user installs `drt` without the [service] extra: the renderer and `drt render` still work."""
    r = run_without({"fastapi", "starlette", "sqlalchemy", "dask", "distributed", "uvicorn", "httpx", "pydantic",
                     "pydantic_settings"}, """
        import renderer.render, renderer.settings.request, renderer.usd.importer
        from service.cli.flags import request_from_args
        from service.cli.main import build_parser
        args = build_parser().parse_args(["render", "x.usda", "-o", "x.exr", "--f-stop", "2.8"])
        req = request_from_args(args)
        assert req.lens.f_stop == 2.8, req
        print("ok")
    """)
    assert r.returncode == 0 and r.stdout.strip().endswith("ok"), r.stderr[-2000:]


# The service's modules by the process that runs them. A group may import the modules of another group only where
# it is declared below (its interfaces); any group but the client may import the shared top-level modules; the
# composition roots build the service from the groups and are imported by none, but for the runtime the API's
# dependencies hand out.
SERVICE_GROUPS = {
    "api": "the API process: routes, bearer token, Server-Timing, presenters, previews, metrics",
    "intake": "the API process and its inspection processes: submission, cost limits, scene checks",
    "queue": "the API process and the coordinator: the job store, the state machine, the change feed, stored scenes",
    "farm": "the coordinator and the Dask workers: dispatcher, cluster, tasks, job files, the monitor's farm view",
    "client": "a user's machine: drt submit/status/fetch over HTTP",
}
SHARED = {"errors", "settings", "spec", "latency"}
ROOTS = {"app", "runtime"}
ROOT_PACKAGES = {"cli"}  # the command line: every parser and its error contract, a composition root of its own
INTERFACES = {  # group -> what it may import of the other groups and the roots (patterns, relative to service)
    "api": {"queue.*", "intake.submission", "farm.job_files", "farm.view", "runtime"},
    "intake": {"queue.*"},
    "queue": set(),
    "farm": {"queue.*"},
    "client": set(),
}


def cross_group_imports(interfaces: dict[str, set[str]]) -> list[str]:
    """Every import of a service module that its group's ``interfaces`` (and SHARED) do not allow."""
    files = {module_name(p).removeprefix("service."): p for p in (ROOT / "service").rglob("*.py")
             if p.name != "__init__.py"}
    bad = []
    for name, path in sorted(files.items()):
        if name in ROOTS or name.split(".")[0] in ROOT_PACKAGES:
            continue
        group = name.split(".")[0] if "." in name else None
        if group is None:
            allowed = SHARED
        else:
            allowed = (set() if group == "client" else SHARED) | interfaces[group]
        for imported in sorted(imported_modules(path)):
            target = imported.removeprefix("service.")
            if not imported.startswith("service.") or target not in files or target == name:
                continue  # not the service's, a package (its __init__ is a docstring), or a name in a module
            if group is not None and target.split(".")[0] == group and "." in target:
                continue
            if not any(fnmatch.fnmatchcase(target, pattern) for pattern in allowed):
                bad.append(f"service.{name} imports service.{target}")
    return bad


def test_service_modules_import_across_process_groups_only_through_declared_interfaces():
    top = {p.stem for p in (ROOT / "service").glob("*.py") if p.name != "__init__.py"}
    assert top == SHARED | ROOTS, "a new top-level module: declare it shared or a root, or put it in a group"
    assert len(top) <= 12
    groups = {p.parent.name for p in (ROOT / "service").glob("*/__init__.py")} - ROOT_PACKAGES
    assert groups == set(SERVICE_GROUPS)
    for g in groups:  # no re-exports: a group's package is its docstring
        body = ast.parse((ROOT / "service" / g / "__init__.py").read_text()).body
        assert len(body) == 1 and isinstance(body[0], ast.Expr), f"service/{g}/__init__.py holds code"
    assert cross_group_imports(INTERFACES) == []


def test_the_group_check_sees_an_undeclared_import():
    narrower = {**INTERFACES, "api": INTERFACES["api"] - {"farm.view"}}
    assert cross_group_imports(narrower) == ["service.api.monitor imports service.farm.view"]


def test_the_client_imports_with_its_extra_alone():
    """`pip install drt[client]` (httpx, pydantic) gives `drt submit/status/fetch`: no FastAPI, SQLAlchemy or Dask."""
    r = run_without({"fastapi", "starlette", "sqlalchemy", "dask", "distributed", "uvicorn", "pydantic_settings",
                     "multipart", "PIL"}, """
        from service.cli.main import build_parser
        from service.client.remote import Client
        args = build_parser().parse_args(["submit", "x.usda", "--spp", "8", "--server", "http://127.0.0.1:1"])
        Client(args.server).close()
        print("ok")
    """)
    assert r.returncode == 0 and r.stdout.strip().endswith("ok"), r.stderr[-2000:]


# ---------------------------------------------------------------------------------------------------------------
# Render settings: declared once, in renderer/settings/options.py's table; everything else is derived from it.

def _setting_cases():
    from renderer.settings.options import SETTINGS_TABLE

    return [pytest.param(s, id=s.name) for s in SETTINGS_TABLE]


def _flag_args(s, value) -> list[str]:
    if s.kind is bool:
        return [s.cli_flag] if value != s.default else []
    if s.shape == "pair":
        return [s.cli_flag, str(value[0]), str(value[1])]
    if s.shape == "many":
        return [a for v in value for a in (s.cli_flag, v)]
    return [s.cli_flag, str(value)]


def _edge_values(s):
    """A value at each bound of a setting (accepted) and one beyond it (refused), from the table alone."""
    inside, outside = [], []
    if s.kind is bool:
        return [not s.default], []
    if s.choices:
        inside = [(s.choices[-1],) if s.shape == "many" else s.choices[-1]]
        outside = [("bogus",) if s.shape == "many" else "bogus"]
        return inside, outside
    if s.kind is str and s.shape == "many":  # a free-form list: the table's example, and a malformed item
        return [tuple(s.example)], [("no equals sign",)] if s.check else []
    if s.kind is str:
        return ["/World/Cam"], ["World/Cam"] if s.check else []
    step = 1 if s.kind is int else 0.5
    for bound, sign, closed in ((s.ge, -1, True), (s.gt, -1, False), (s.le, 1, True), (s.lt, 1, False)):
        if bound is None:
            continue
        edge = s.kind(bound) if closed else bound - sign * step
        inside.append(edge)
        outside.append(s.kind(bound + sign * step) if closed else s.kind(bound))
    if s.shape == "pair":
        inside = [(v, v) for v in inside]
        outside = [(v, v) for v in outside]
    return inside, outside


@pytest.mark.parametrize("s", _setting_cases())
def test_the_cli_derives_each_setting_from_the_table(s):
    """`drt render` and `drt submit` take the table's flag, accept its bounds, refuse beyond them, and a flag not given
    leaves the table's default."""
    from service.cli.flags import request_from_args
    from service.cli.main import build_parser
    from service.cli.client import settings_from_args

    parser = build_parser()
    base = ["render", "scene.usda", "-o", "out.exr"]
    default = request_from_args(parser.parse_args(base)).settings()
    if s.name != "tile":  # the tile size is execution, never part of the request
        expected = s.default
        assert default[s.name] == expected, s.name
    inside, outside = _edge_values(s)
    for v in inside:
        args = parser.parse_args(base + _flag_args(s, v))
        got = getattr(args, s.name)
        assert (tuple(got) if s.shape in ("pair", "many") else got) == v
        sub = settings_from_args(parser.parse_args(["submit", "scene.usda"] + _flag_args(s, v)))
        assert sub[s.name] == (list(v) if s.shape in ("pair", "many") else v)
    for v in outside:
        with pytest.raises(SystemExit):
            parser.parse_args(base + _flag_args(s, v))


@pytest.mark.parametrize("s", _setting_cases())
def test_the_wire_format_and_openapi_derive_each_setting_from_the_table(s):
    """schemas.RenderSettings' default and bounds are the table's, and so is what OpenAPI documents."""
    import pydantic

    from schemas import JobCreate
    from service.app import create_app
    from service.settings import ServiceSettings

    field = JobCreate.model_fields[s.name]
    assert field.default == (list(s.default) if s.shape == "many" else s.default)
    assert field.description == s.describe()
    inside, outside = _edge_values(s)
    for v in inside:
        JobCreate(**{s.name: v})
    for v in outside:
        with pytest.raises(pydantic.ValidationError):
            JobCreate(**{s.name: v})
    schema = JobCreate.model_json_schema()["properties"][s.name]
    if s.kind in (int, float) and s.shape == "one":
        numbers = next((o for o in schema.get("anyOf", [schema]) if o.get("type") in ("integer", "number")), {})
        for key, bound in (("minimum", s.ge), ("maximum", s.le), ("exclusiveMinimum", s.gt),
                           ("exclusiveMaximum", s.lt)):
            assert numbers.get(key) == bound, (s.name, key)
    global _OPENAPI
    if "_OPENAPI" not in globals():
        _OPENAPI = create_app(ServiceSettings(data_dir="/nonexistent-not-started")).openapi()
    assert s.name in str(_OPENAPI)


SETTINGS_HOME = ROOT / "renderer" / "settings" / "options.py"
SCENE_MODEL = ROOT / "renderer" / "scene" / "model.py"  # what a loaded scene holds (a camera's own f-stop), not settings


def test_no_setting_is_declared_outside_the_table():
    """No flag string of a setting is written anywhere but the table, and no record that carries settings (a class with
    three or more fields named like settings: a pydantic model, a dataclass) gives one a literal default: such
    records take ``options.default_of`` (the table's default), or no default."""
    from renderer.settings.options import SETTINGS_TABLE

    flags = {s.cli_flag for s in SETTINGS_TABLE}
    names = {s.name for s in SETTINGS_TABLE}
    bad = []
    for top in ("renderer", "schemas", "service"):
        for p in (ROOT / top).rglob("*.py"):
            if p in (SETTINGS_HOME, SCENE_MODEL):
                continue
            tree = ast.parse(p.read_text(), str(p))
            for node in ast.walk(tree):
                if isinstance(node, ast.Constant) and node.value in flags:
                    bad.append(f"{p.relative_to(ROOT)}:{node.lineno}: flag {node.value}")
                if not isinstance(node, ast.ClassDef):
                    continue
                fields = [f for f in node.body if isinstance(f, ast.AnnAssign) and isinstance(f.target, ast.Name)
                          and f.target.id in names]
                if len(fields) < 3:
                    continue
                for f in fields:
                    if f.value is not None and getattr(getattr(f.value, "func", None), "id", "") != "default_of":
                        bad.append(f"{p.relative_to(ROOT)}:{f.lineno}: {node.name}.{f.target.id}")
    assert not bad, "settings declared outside renderer/settings/options.py:\n" + "\n".join(bad)


def test_the_architecture_document_names_every_module():
    """docs/architecture.md is the one place that lists modules: each module of the three packages is named there, by
    its path in backticks, or in a table row that names its package's folder and the module's name in backticks."""
    doc = (ROOT / "docs" / "architecture.md").read_text()
    rows = [line for line in doc.splitlines() if line.startswith("|")]
    missing = []
    for top in ("renderer", "service", "schemas"):
        for p in sorted((ROOT / top).rglob("*.py")):
            if p.name in ("__init__.py", "__main__.py"):
                continue
            rel = p.relative_to(ROOT)
            folder = f"`{rel.parent.as_posix()}/"
            named = f"`{rel.as_posix()}`" in doc or any(folder in r and f"`{p.stem}`" in r for r in rows)
            if not named:
                missing.append(rel.as_posix())
    assert not missing, "modules docs/architecture.md does not name: " + ", ".join(missing)
