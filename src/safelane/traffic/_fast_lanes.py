"""Optional compiled kernel of the changers' neighbour search (numba, extra ``fast``). Not a twin: it holds no code of
its own. :func:`.lanes.neighbour_rows` itself is given to ``numba.njit`` (with :func:`.lanes._first` registered for
it), so the compiled path and the Python one are the same source; ``tests/test_traffic_situation.py`` runs both
against the reference written there. Imported only where numba imports and ``SAFELANE_NO_NUMBA`` is not ``1``
(:func:`.lanes._kernel`)."""

from __future__ import annotations

import numba

from ..safety._fast_base import announce_compiles
from . import lanes

announce_compiles()
numba.extending.register_jitable(lanes._first)
neighbour_kernel = numba.njit(cache=True, nogil=True)(lanes.neighbour_rows)
