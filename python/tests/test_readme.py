"""python/README.md against the type stub `augsim/_augsim.pyi`, and the stub against the built
module: the documented signatures (parameter names, kinds and defaults) and result fields."""

import ast
import inspect
import os
import re

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
README = os.path.join(HERE, "..", "README.md")
STUB = os.path.join(HERE, "..", "augsim", "_augsim.pyi")


def stub():
    """The stub's functions, classes and constants: name -> ast node."""
    with open(STUB, encoding="utf-8") as f:
        tree = ast.parse(f.read())
    named = {n.name: n for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
    constants = {n.target.id: n for n in tree.body if isinstance(n, ast.AnnAssign)}
    return {**named, **constants}


def methods(cls):
    return {n.name: n for n in cls.body if isinstance(n, ast.FunctionDef)}


def fields(cls):
    return [n.target.id for n in cls.body if isinstance(n, ast.AnnAssign)]


def parameters(function, drop_self):
    """(name, kind, default as source) of a function's parameters."""
    a = function.args
    positional = a.posonlyargs + a.args
    defaults = [None] * (len(positional) - len(a.defaults)) + [ast.unparse(d) for d in a.defaults]
    out = [(p.arg, "positional", d) for p, d in zip(positional, defaults)]
    out += [(p.arg, "keyword", None if d is None else ast.unparse(d)) for p, d in zip(a.kwonlyargs, a.kw_defaults)]
    return out[1:] if drop_self else out


def documented(text):
    """The README's signatures: `augsim.NAME(...)` in bold, and `- `.NAME(...)`` under the
    class documented last; (class or None, name, parameters source)."""
    found, current = [], None
    for line in text.splitlines():
        top = re.match(r"\*\*`augsim\.(\w+)\((.*?)\)(?: -> \w+)?`\*\*", line)
        if top:
            name = top.group(1)
            current = name if name[0].isupper() else None
            found.append((None, name, top.group(2)))
            continue
        method = re.match(r"- `\.(\w+)\((.*?)\)(?: -> \w+)?`", line)
        if method and current:
            found.append((current, method.group(1), method.group(2)))
    return found


def readme_parameters(source):
    return parameters(ast.parse(f"def f({source}): pass").body[0], drop_self=False)


def test_the_readme_documents_the_stubs_signatures():
    with open(README, encoding="utf-8") as f:
        text = f.read()
    s = stub()
    signatures = documented(text)
    names = {(cls, name) for cls, name, _ in signatures}
    for expected in [(None, "solve"), (None, "Registration"), ("Registration", "register"), (None, "predict"),
                     (None, "Assimilation"), ("Assimilation", "step")]:
        assert expected in names, f"README does not document {expected}"
    for cls, name, source in signatures:
        if cls is None and name[0].isupper():
            stubbed, drop_self = methods(s[name])["__init__"], True
        elif cls is None:
            stubbed, drop_self = s[name], False
        else:
            stubbed, drop_self = methods(s[cls])[name], True
        assert readme_parameters(source) == parameters(stubbed, drop_self), f"{cls or 'augsim'}.{name}"


def test_the_readme_names_every_result_field():
    with open(README, encoding="utf-8") as f:
        text = f.read()
    s = stub()
    for cls in ["Solution", "Registered", "Estimate"]:
        for field in fields(s[cls]):
            assert f"`{field}`" in text, f"README does not name {cls}.{field}"


def test_the_stub_matches_the_built_module():
    native = pytest.importorskip("augsim._augsim", reason="the augsim package is not installed")
    for name, node in stub().items():
        assert hasattr(native, name), f"the module has no {name}"
        if isinstance(node, ast.ClassDef):
            cls = getattr(native, name)
            for member in fields(node) + [m for m in methods(node) if m != "__init__"]:
                assert hasattr(cls, member), f"{name}.{member} is stubbed but not in the module"
            signature = inspect.signature(cls) if "__init__" in methods(node) else None
            if signature is not None:
                stubbed = [p for p, _, _ in parameters(methods(node)["__init__"], drop_self=True)]
                assert list(signature.parameters) == stubbed, name
        elif isinstance(node, ast.FunctionDef):
            stubbed = [p for p, _, _ in parameters(node, drop_self=False)]
            assert list(inspect.signature(getattr(native, name)).parameters) == stubbed, name
        else:
            assert isinstance(getattr(native, name), int), f"{name} is stubbed as an int"


def test_the_module_has_nothing_the_stub_leaves_out():
    native = pytest.importorskip("augsim._augsim", reason="the augsim package is not installed")
    s = stub()
    public = [n for n in dir(native) if not n.startswith("_")]
    assert sorted(n for n in public if n not in s) == [], "in the module but not in the stub"
    for name, node in s.items():
        # (The exception and warning classes' members are Python's own.)
        if isinstance(node, ast.ClassDef) and name not in ("AugsimError", "AugsimWarning"):
            stubbed = set(fields(node)) | set(methods(node))
            members = [m for m in dir(getattr(native, name)) if not m.startswith("_")]
            assert sorted(m for m in members if m not in stubbed) == [], f"{name}: in the module but not in the stub"
