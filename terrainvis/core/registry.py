"""One registry of named entries, the rules every registry of terrainvis shares.

The simplification methods (:data:`simplifiers.METHODS`), the relocations
(:data:`terrainvis.relocation.RELOCATIONS`), the LOS engines
(:data:`terrainvis.visibility.engines.ENGINES`) and the comparison's measures
(:data:`terrainvis.experiment.measures.MEASURES`) are each a :class:`Registry`: a dict from
name to entry, in registry order (the order of tables and figures), that knows which
entries are built in. Each family's ``register`` checks what is particular to its entries
(a method's signature, an engine's terrains) and leaves to the registry what is common:

* a name is a plain word (:func:`terrainvis.core.validate.entry_name`), since it becomes
  part of file names and table cells;
* a built-in entry is never replaced or removed;
* a name taken by an entry registered earlier is replaced only with ``replace=True``;
* :meth:`Registry.names` lists the names, :meth:`Registry.remove` removes one, each
  family's ``available()`` and ``unregister()`` are these;
* :meth:`Registry.watch` calls a function after every change, for what is made from the
  entries and kept elsewhere (``compare``'s signature and docstring hold the relocations'
  own options).

:func:`registry` finds a family's registry by its kind, for code that reads entries
without importing the module that defines them (the report reads a measure's ``counts``,
and the measures' entries name report tables of their own).
"""

from __future__ import annotations

from .validate import entry_name

__all__ = ["Registry", "registry"]

#: The first registry made of each kind.
_BY_KIND: dict[str, "Registry"] = {}


def registry(kind: str) -> "Registry | None":
    """The registry of ``kind`` (``"method"``, ``"relocation"``, ``"engine"``, ``"measure"``),
    None while the module that makes it is not imported."""
    return _BY_KIND.get(kind)


class Registry(dict):
    """Named entries of one kind, in registry order, with the entries built in.

    Parameters
    ----------
    kind : str
        What an entry is, for messages: ``"method"``, ``"relocation"``, ...
    entries : dict
        The built-in entries, by name (every one of them is built in).

    Examples
    --------
    >>> r = Registry("colour", {"red": 1})
    >>> r.add("teal", 2)
    2
    >>> r.names(), sorted(r.builtin)
    (['red', 'teal'], ['red'])
    >>> r.add("red", 3)
    Traceback (most recent call last):
    ...
    ValueError: colour 'red' is built in and cannot be replaced; register yours under another name
    >>> r.remove("teal")
    2
    """

    def __init__(self, kind: str, entries: dict):
        super().__init__(entries)
        self.kind = kind
        self.builtin = frozenset(self)
        self._watchers = []
        _BY_KIND.setdefault(kind, self)  # an unpickled copy skips __init__: it is never registry(kind)'s

    def watch(self, listener) -> None:
        """Call ``listener()`` after every later change of the entries (one registered,
        replaced or removed: an item set, deleted or popped)."""
        self._watchers.append(listener)

    def __setitem__(self, name, entry):
        super().__setitem__(name, entry)
        self._changed()

    def __delitem__(self, name):
        super().__delitem__(name)
        self._changed()

    def pop(self, name, *default):
        out = super().pop(name, *default)
        self._changed()
        return out

    def _changed(self) -> None:
        for listener in getattr(self, "_watchers", ()):  # (an unpickled copy has none)
            listener()

    def __getstate__(self):
        state = dict(self.__dict__)
        state.pop("_watchers", None)  # a copy in another process tells no one here
        return state

    def _a(self) -> str:
        return "an" if self.kind[:1] in "aeiou" else "a"

    def check_new(self, name, *, replace: bool = False) -> str:
        """``name`` if an entry may be registered under it (a plain word, not built in, free or
        ``replace``), else a ValueError saying why."""
        entry_name(name, self.kind)
        if name in self.builtin:
            raise ValueError(f"{self.kind} {name!r} is built in and cannot be replaced; register yours under another "
                             "name")
        if name in self and not replace:
            raise ValueError(f"{self._a()} {self.kind} named {name!r} is registered already; pass replace=True to "
                             "replace it, or choose another name")
        return name

    def add(self, name, entry, *, replace: bool = False):
        """Register ``entry`` under ``name`` (after the others, or in place of the entry it
        replaces) and return it; see :meth:`check_new`. A family whose ``register`` checks
        the name first, before its own checks, then stores the entry itself."""
        self[self.check_new(name, replace=replace)] = entry
        return entry

    def remove(self, name):
        """Remove an entry registered from outside and return it (built-in ones stay)."""
        if name in self.builtin:
            raise ValueError(f"{self.kind} {name!r} is built in and cannot be removed")
        if name not in self:
            raise ValueError(f"no {self.kind} named {name!r} is registered; the {self.kind}s are {self.names()}")
        return self.pop(name)

    def names(self) -> list[str]:
        """Every entry's name, in registry order."""
        return list(self)

