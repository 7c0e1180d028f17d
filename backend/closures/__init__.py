"""Building modes and trouble: what is closed to robots, now or between two times (docs/server.md,
"Building modes and trouble").

One notion of *closed* for both: staff close a gallery (a restricted area), a set of nodes, a
door or an elevator (``Closure``, kept in the database); a door that does not open or a lift
that does not come closes itself for a while (``TroubleWatch``). Paths avoid every closed node
(``routing.path_avoiding``); a goal that only closed nodes reach is refused with the reason,
and a tour skips it."""

from backend.closure import Closure, ClosureError, ClosureKind
from backend.detours import RouteClosed, path_avoiding

__all__ = ["Closure", "ClosureError", "ClosureKind", "RouteClosed", "path_avoiding"]
