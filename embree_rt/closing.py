"""Objects that hold Embree scenes or worker pools: closed by ``close()`` or on leaving a ``with``
block."""

from __future__ import annotations

from typing import Self


class Closing:
    """Base of the classes that own something to release: ``with`` returns the object itself and
    calls its ``close`` on the way out, whether or not the block raised."""

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
