"""Methods from outside the package: plugin modules and the ``lidarcam.methods`` entry-point group.

A plugin is either

- a **module** that registers its methods when imported (``calib_core.registry.register(Method(...))``), named
  on the command line (``lidarcam --plugin my_lab.my_method``) or in a sweep (``methods.plugins=[...]``), or
- an **entry point** of the group ``lidarcam.methods`` in an installed distribution's metadata, e.g. in its
  ``pyproject.toml``: ``[project.entry-points."lidarcam.methods"] my_method = "my_lab.my_method"`` (a module,
  as above) or ``= "my_lab.my_method:methods"`` (a callable returning a ``Method``, several, or None when it
  registered them itself).

A method a plugin registers with the default origin gets the plugin's module (or entry point) as its origin.
A plugin that cannot be imported, or that registers a name already taken, is a ``PluginError`` of one line
naming the plugin. Loading is explicit (the CLI and the experiment runner call it), never on ``import
calib_core``, and idempotent: a module already loaded registers nothing twice.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import sys
from collections.abc import Iterable
from dataclasses import replace
from types import ModuleType

from .errors import CalibrationError, LidarcamError
from .registry import METHODS, Method, register

ENTRY_POINT_GROUP = "lidarcam.methods"
DEFAULT_ORIGIN = Method.__dataclass_fields__["origin"].default

_LOADED: dict[str, tuple[str, ...]] = {}
"""Plugins loaded in this process: plugin name -> the method names it added."""
_INSTALLED_LOADED = False


class PluginError(LidarcamError):
    """A plugin cannot be loaded (import error, a name already registered, a bad return value)."""


def _adopt(new: Iterable[str], origin: str) -> None:
    """Give the methods ``new`` the plugin's ``origin`` where they kept the default one."""
    for name in new:
        if METHODS[name].origin == DEFAULT_ORIGIN:
            METHODS[name] = replace(METHODS[name], origin=origin)


def _register_returned(value, label: str, origin: str) -> None:
    if value is None:
        return
    items = [value] if isinstance(value, Method) else value
    try:
        items = list(items)
    except TypeError:
        raise PluginError(f"plugin {label}: returned {type(value).__name__}, expected Method(s) or None") from None
    for m in items:
        if not isinstance(m, Method):
            raise PluginError(f"plugin {label}: returned {type(m).__name__}, expected calib_core.registry.Method")
        register(replace(m, origin=origin) if m.origin == DEFAULT_ORIGIN else m)


def _guard(label: str, load):
    """Run ``load()``; return the method names it registered, errors turned into one-line PluginErrors."""
    if label in _LOADED:
        return _LOADED[label]
    before = set(METHODS)
    try:
        load()
    except Exception as exc:  # noqa: BLE001 -- whatever the plugin raises: one line naming it
        for name in [n for n in METHODS if n not in before]:  # nothing half-registered stays
            del METHODS[name]
        if isinstance(exc, PluginError):
            raise
        if isinstance(exc, CalibrationError):  # a name already registered
            raise PluginError(f"plugin {label}: {exc}") from None
        raise PluginError(f"plugin {label}: cannot load ({type(exc).__name__}: {exc})") from None
    new = tuple(n for n in METHODS if n not in before)
    _LOADED[label] = new
    return new


def load_module(name: str) -> tuple[str, ...]:
    """Import the plugin module ``name`` (it registers its methods); the method names it added."""
    def load() -> ModuleType:
        return importlib.import_module(name)

    new = _guard(name, load)
    _adopt(new, name)
    return new


def reload_module(name: str) -> tuple[str, ...]:
    """Re-import the plugin module ``name`` after its file changed: the methods it registered are dropped and
    registered again by the new code; the method names it added (PluginError, one line, if it now fails)."""
    for method in _LOADED.pop(name, ()):
        METHODS.pop(method, None)

    def load() -> ModuleType:
        module = sys.modules.get(name)
        importlib.invalidate_caches()
        return importlib.reload(module) if module is not None else importlib.import_module(name)

    new = _guard(name, load)
    _adopt(new, name)
    return new


def load_entry_point(ep: importlib.metadata.EntryPoint) -> tuple[str, ...]:
    """Load one entry point of ``lidarcam.methods``: a module (registers on import) or a callable."""
    label, module = ep.value, ep.value.split(":")[0]

    def load() -> None:
        obj = ep.load()
        if not isinstance(obj, ModuleType):
            if not callable(obj):
                raise PluginError(f"plugin {label}: is {type(obj).__name__}, expected a module or a callable")
            _register_returned(obj(), label, module)

    new = _guard(label, load)
    _adopt(new, module)
    return new


def entry_points() -> tuple[importlib.metadata.EntryPoint, ...]:
    """The installed entry points of the group ``lidarcam.methods``."""
    return tuple(importlib.metadata.entry_points(group=ENTRY_POINT_GROUP))


def load_plugins(modules: Iterable[str] = (), *, installed: bool = True) -> tuple[str, ...]:
    """Load the entry points of ``lidarcam.methods`` (when ``installed``) and then the plugin ``modules``;
    returns the method names added now. PluginError (one line, naming the plugin) on the first that fails."""
    global _INSTALLED_LOADED
    new: list[str] = []
    if installed and not _INSTALLED_LOADED:
        for ep in entry_points():
            new += load_entry_point(ep)
        _INSTALLED_LOADED = True
    for name in modules:
        new += load_module(str(name))
    return tuple(new)


def loaded() -> dict[str, tuple[str, ...]]:
    """The plugins loaded in this process and the method names each added."""
    return dict(_LOADED)
