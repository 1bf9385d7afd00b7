"""Name -> class registries for plugins (matchers, sources, sinks, datasets, sensors)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Generic, TypeVar

T = TypeVar("T")


class Registry(Generic[T]):
    """A mapping of plugin names to the classes that implement them.

    ``Registry[Matcher]`` holds subclasses of ``Matcher``: :meth:`get` returns
    ``type[Matcher]``, so class attributes (``Options``, ``supports_guidance``,
    ``detect``...) type-check at the call sites.

    Parameters
    ----------
    kind : str
        What the registry holds ("matcher", "source", ...); used in error messages.

    Examples
    --------
    >>> class Matcher: ...
    >>> MATCHERS: Registry[Matcher] = Registry("matcher")
    >>> @MATCHERS.register("sgbm")
    ... class SGBM(Matcher): ...
    >>> MATCHERS.get("sgbm") is SGBM
    True
    """

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self._items: dict[str, type[T]] = {}

    def register(self, name: str) -> Callable[[type[T]], type[T]]:
        """Class decorator registering the decorated class under ``name``.

        Parameters
        ----------
        name : str
            Registered name; must not be taken yet.

        Returns
        -------
        callable
            The decorator; it returns the class unchanged.

        Raises
        ------
        ValueError
            If ``name`` is already registered (raised when the decorator is applied).
        """

        def decorator(cls: type[T]) -> type[T]:
            if name in self._items:
                raise ValueError(f"{self.kind} {name!r} is already registered")
            self._items[name] = cls
            return cls

        return decorator

    def get(self, name: str) -> type[T]:
        """Return the class registered as ``name``.

        Raises
        ------
        ValueError
            If no such plugin exists; the message lists the known names.
        """
        try:
            return self._items[name]
        except KeyError:
            known = ", ".join(sorted(self._items)) or "(none)"
            raise ValueError(f"unknown {self.kind} {name!r}; known: {known}") from None

    def names(self) -> list[str]:
        """Sorted registered names."""
        return sorted(self._items)

    def __contains__(self, name: object) -> bool:
        return name in self._items

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())
