"""The tree shows the design: imports run one way (posedyn <- absorber <- service), no module
imports another's private name or private module, project modules are imported at the top of
a module (function-local imports only for heavy optional packages, with their reason on the
line), every package says what lives in it, and both ways into the CLI list the same commands."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("posedyn", "absorber", "service")
#: What each package may import from the project (itself included).
ALLOWED = {"posedyn": {"posedyn"}, "absorber": {"posedyn", "absorber"}, "service": {"posedyn", "absorber", "service"}}


def modules():
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            yield package, path


def imports(path: Path):
    """(node, imported module, names, inside a function) of every import in a file."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    functions = [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
    local = {id(sub) for f in functions for sub in ast.walk(f)}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 0:
            yield node, node.module, [a.name for a in node.names], id(node) in local
        elif isinstance(node, ast.Import):
            for alias in node.names:
                yield node, alias.name, [], id(node) in local


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def test_imports_run_one_way():
    bad = []
    for package, path in modules():
        for node, module, _, _ in imports(path):
            root = module.split(".")[0]
            if root in PACKAGES and root not in ALLOWED[package]:
                bad.append(f"{path.relative_to(ROOT)}:{node.lineno} imports {module}")
    assert not bad, "\n".join(bad)


def test_no_module_imports_a_private_name_or_module_of_another():
    bad = []
    for _, path in modules():
        here = module_name(path)
        for node, module, names, _ in imports(path):
            if module.split(".")[0] not in PACKAGES:
                continue
            private_module = [p for p in module.split(".") if p.startswith("_")]
            # a package's own private modules are its business
            owner = module.rsplit(".", 1)[0] if private_module else None
            if private_module and not (here == owner or here.startswith(owner + ".")):
                bad.append(f"{path.relative_to(ROOT)}:{node.lineno} imports the private module {module}")
            for name in names:
                if name.startswith("_") and name != "__version__":
                    bad.append(f"{path.relative_to(ROOT)}:{node.lineno} imports the private name {name} from {module}")
    assert not bad, "\n".join(bad)


def test_function_local_imports_are_heavy_optional_packages_with_a_reason():
    bad = []
    for _, path in modules():
        lines = path.read_text(encoding="utf-8").splitlines()
        for node, module, _, local in imports(path):
            if not local:
                continue
            if module.split(".")[0] in PACKAGES or "#" not in lines[node.lineno - 1]:
                bad.append(f"{path.relative_to(ROOT)}:{node.lineno}: {lines[node.lineno - 1].strip()}")
    assert not bad, "function-local imports must be heavy optional packages with a '# reason':\n" + "\n".join(bad)


def test_every_package_has_a_docstring():
    missing = []
    for package in PACKAGES:
        for init in sorted((ROOT / package).rglob("__init__.py")):
            if not ast.get_docstring(ast.parse(init.read_text(encoding="utf-8"))):
                missing.append(str(init.relative_to(ROOT)))
    assert not missing, missing


def test_the_test_sees_a_violation(tmp_path):
    """The checks above can fail: a posedyn module importing service is caught."""
    fake = tmp_path / "m.py"
    fake.write_text("def f():\n    from service.cli import main\n")
    found = list(imports(fake))
    assert found and found[0][1] == "service.cli" and found[0][3] is True


def _commands(args):
    out = subprocess.run(args + ["--help"], capture_output=True, text=True, cwd=ROOT, env={"COLUMNS": "200", "PATH": "/usr/bin:/bin"})
    assert out.returncode == 0, out.stderr
    names = set()
    for line in out.stdout.splitlines():
        if not (line.startswith("│ ") and line[2:3].isalpha()):
            continue  # a command's name stands right after the box edge; wrapped help is indented
        name = line[2:].split()[0]
        if name != "--version" and name.replace("-", "").isalpha():
            names.add(name)
    return names


def test_python_m_service_and_the_installed_script_list_the_same_commands():
    script = Path(sys.executable).parent / "posedyn"
    if not script.exists():
        pytest.skip("the posedyn script is not installed next to this interpreter")
    module = _commands([sys.executable, "-m", "service"])
    installed = _commands([str(script)])
    assert module == installed
    assert {"sweep", "serve", "query", "gap", "gap-campaign", "schedule", "chatter", "train"} <= module
