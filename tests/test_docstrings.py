"""Documentation of the public API, in the manner of python-control's ``docstrings_test.py``.

The public API is what the packages export in ``__all__`` (``envs``, ``controllers``,
``agents``, ``commands``) and the ``configure``/``run`` pair of every ``roughwalk`` sub-command:
the functions, the classes, and the public methods and properties that the classes define in
this project (methods inherited from a library class keep that library's documentation). The
rules:

- every public function, class, method and property has a docstring (a method overriding a
  documented method may inherit its docstring; a class may not, nor may a dataclass rely on
  the signature that ``dataclass`` writes in place of a docstring);
- every parameter of a public function or method appears, as a word, in its docstring; the
  parameters of a class's constructor appear in the class docstring or in ``__init__``'s.
  ``self``, ``cls``, ``*args`` and ``**kwargs`` are exempt.
"""

from __future__ import annotations

import importlib
import inspect
import re
from collections.abc import Callable, Iterator

import pytest

import commands

PACKAGES = ("envs", "controllers", "agents", "commands")


def _project_object(obj: object) -> bool:
    """Whether ``obj`` is defined in one of the project's packages."""
    return (getattr(obj, "__module__", None) or "").split(".")[0] in PACKAGES


def _function(obj: object) -> Callable | None:
    """The Python function behind ``obj`` (a numba dispatcher's ``py_func``), or None."""
    obj = getattr(obj, "py_func", obj)
    return obj if inspect.isfunction(obj) else None


def _members(cls: type) -> Iterator[tuple[str, object]]:
    """Public methods and properties that ``cls`` and its project base classes define."""
    seen: set[str] = set()
    for klass in cls.__mro__:
        if not _project_object(klass):
            continue
        for name, attr in vars(klass).items():
            if name.startswith("_") or name in seen:
                continue
            seen.add(name)
            if isinstance(attr, staticmethod | classmethod):
                attr = attr.__func__
            if isinstance(attr, property) or _function(attr) is not None:
                yield name, attr


def public_api() -> Iterator[tuple[str, object]]:
    """``(qualified name, object)`` of every function, class, method and property checked."""
    seen: set[int] = set()
    exported: list[tuple[str, object]] = []
    for pkg in PACKAGES:
        module = importlib.import_module(pkg)
        exported += [(f"{pkg}.{name}", getattr(module, name)) for name in module.__all__]
    for name, (module_name, _) in commands.COMMANDS.items():
        module = importlib.import_module(module_name)
        exported += [(f"commands.{name}.{f}", getattr(module, f)) for f in ("configure", "run")]
    for qualname, obj in exported:
        if id(obj) in seen or not (inspect.isclass(obj) or _function(obj) is not None):
            continue
        seen.add(id(obj))
        yield qualname, obj
        if inspect.isclass(obj):
            for name, member in _members(obj):
                yield f"{qualname}.{name}", member


def _own_class_doc(cls: type) -> str:
    """The class's own docstring ('' if it has none or only the one ``dataclass`` writes)."""
    doc = cls.__dict__.get("__doc__") or ""
    if doc.startswith(f"{cls.__name__}("):  # dataclass's stand-in: the signature
        return ""
    return inspect.cleandoc(doc)


def _documented(name: str, doc: str) -> bool:
    """Whether parameter ``name`` appears as a word in ``doc``."""
    return re.search(rf"(?<![\w]){re.escape(name)}(?![\w])", doc) is not None


def _parameters(func: Callable) -> list[str]:
    """Parameter names of ``func`` that must be documented."""
    params = list(inspect.signature(func).parameters.values())
    if params and params[0].name in ("self", "cls"):
        params = params[1:]
    varargs = (inspect.Parameter.VAR_POSITIONAL, inspect.Parameter.VAR_KEYWORD)
    return [p.name for p in params if p.kind not in varargs]


def gaps(qualname: str, obj: object) -> list[str]:
    """The documentation gaps of one public object (see the module docstring)."""
    if isinstance(obj, property):
        return [] if inspect.getdoc(obj) else [qualname]
    if inspect.isclass(obj):
        doc = _own_class_doc(obj)
        init = obj.__dict__.get("__init__")
        init_doc = inspect.cleandoc(getattr(init, "__doc__", None) or "")
        found = [] if doc else [qualname]
        if "__init__" in obj.__dict__ or "__dataclass_fields__" in obj.__dict__:
            names = _parameters(obj.__init__)
            found += [f"{qualname}({n})" for n in names if not _documented(n, f"{doc}\n{init_doc}")]
        return found
    func = _function(obj)
    doc = inspect.getdoc(obj) or inspect.getdoc(func) or ""
    if not doc:
        return [qualname]
    return [f"{qualname}({n})" for n in _parameters(func) if not _documented(n, doc)]


API = sorted(public_api(), key=lambda item: item[0])


@pytest.mark.parametrize(("qualname", "obj"), API, ids=[name for name, _ in API])
def test_public_object_is_documented(qualname: str, obj: object) -> None:
    found = gaps(qualname, obj)
    assert not found, f"undocumented: {', '.join(found)}"


def test_the_walk_covers_every_package() -> None:
    walked = {name.split(".")[0] for name, _ in API}
    assert walked == set(PACKAGES)
    assert "agents.ResidualWrapper.step" in dict(API)
    assert "commands.demo.run" in dict(API)
