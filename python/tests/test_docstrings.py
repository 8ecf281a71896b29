"""Every public name of the package has a docstring: its modules, functions, classes and
their methods and properties — the native module's (from Rust's doc comments), the Python
layer's and trep's drop-in."""
import importlib
import inspect
import pkgutil

import tree_mech


def public_modules():
    yield tree_mech
    yield importlib.import_module("tree_mech._native")
    for info in pkgutil.walk_packages(tree_mech.__path__, "tree_mech."):
        if not any(part.startswith("_") for part in info.name.split(".")[1:]):
            yield importlib.import_module(info.name)


def undocumented():
    missing, seen = [], set()

    def check(name, obj):
        # inspect.getdoc: a method overriding a documented one inherits its docstring.
        if not (inspect.getdoc(obj) or "").strip():
            missing.append(name)

    for module in public_modules():
        check(module.__name__, module)
        for name, obj in vars(module).items():
            if name.startswith("_") or inspect.ismodule(obj):
                continue
            # Names a module imports from elsewhere are checked where they are defined.
            home = getattr(obj, "__module__", module.__name__) or ""
            if not home.startswith("tree_mech") or id(obj) in seen:
                continue
            if not (inspect.isclass(obj) or callable(obj)):
                continue
            seen.add(id(obj))
            check(f"{module.__name__}.{name}", obj)
            if inspect.isclass(obj):
                for attribute, member in vars(obj).items():
                    if attribute.startswith("_"):
                        continue
                    if callable(member) or isinstance(member, (property, staticmethod, classmethod)):
                        check(f"{module.__name__}.{name}.{attribute}", getattr(obj, attribute))
    return missing


def test_every_public_name_has_a_docstring():
    missing = undocumented()
    assert not missing, "no docstring: " + ", ".join(missing)
