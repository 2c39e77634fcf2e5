# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Attributes kept in a float array, so that compiled code and Python share them."""

from __future__ import annotations

from typing import Any

__all__ = ['Slot']


class Slot:
    """An attribute kept in element ``index`` of the instance's float array ``array``
    (``kind`` int: read as an int)."""

    def __init__(self, array: str, index: int, kind: type = float) -> None:
        self.array, self.index, self.kind = array, index, kind

    def __get__(self, obj: Any, owner: Any = None) -> Any:
        if obj is None:
            return self
        v = getattr(obj, self.array).item(self.index)
        return int(v) if self.kind is int else v

    def __set__(self, obj: Any, value: float) -> None:
        getattr(obj, self.array)[self.index] = value
