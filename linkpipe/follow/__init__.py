"""Follow a log while it is written (``python -m linkpipe follow``): :mod:`.tail` reads the
growing log, :mod:`.blocks` solves its rows once final, :mod:`.run` is the loop."""
from .run import Outcome, follow

__all__ = ["follow", "Outcome"]
