"""The errors of reading recordings, in one place.

:class:`BagError` is the one a caller catches: a recording that cannot be read or analysed, beyond
the reading limits, or refused; its message names the problem. :class:`ChunkTooLarge` is raised
while inflating a chunk that produces more bytes than it declares (inside the reader, where it
becomes a skipped chunk or a :class:`BagError`). The writer raises the standard errors
(``FileExistsError``, ``OSError``, ``ValueError``, ``KeyError``); see :mod:`.writer`.
"""

from __future__ import annotations


class BagError(ValueError):
    """The recording cannot be read or analysed; the message names the problem."""


class ChunkTooLarge(ValueError):
    """A chunk inflates to more bytes than it declares."""
