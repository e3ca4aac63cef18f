"""``cached_property`` without a lock on every Python the package supports.

Before 3.12, :class:`functools.cached_property` holds one ``RLock`` per attribute, shared by all instances: a
thread inside any system's cached property then blocks every other thread's first read of it on every
instance, and a process forked at that moment hangs in the child at its first read (an audit: 1 forked child
in 30 while another thread integrated). 3.12 dropped the lock; this is that behaviour for 3.10 and 3.11. Two
threads reading a fresh attribute at once may both compute it (the values are equal: pure functions of the
instance); the last one stays.
"""

from __future__ import annotations

import sys
from functools import cached_property as _functools_cached_property

__all__ = ["cached_property"]

if sys.version_info >= (3, 12):
    cached_property = _functools_cached_property
else:
    class cached_property:  # noqa: N801 (the name of what it stands for)
        """A non-data descriptor computing ``func(instance)`` once and storing it in the instance's ``__dict__``."""

        def __init__(self, func):
            self.func = func
            self.attrname = None
            self.__doc__ = func.__doc__
            self.__module__ = func.__module__

        def __set_name__(self, owner, name):
            if self.attrname is None:
                self.attrname = name
            elif name != self.attrname:
                raise TypeError(f"Cannot assign the same cached_property to two different names "
                                f"({self.attrname!r} and {name!r}).")

        def __get__(self, instance, owner=None):
            if instance is None:
                return self
            if self.attrname is None:
                raise TypeError("Cannot use cached_property instance without calling __set_name__ on it.")
            value = self.func(instance)
            instance.__dict__[self.attrname] = value
            return value
