"""The closed forms moved to :mod:`linkpipe.closed_forms`; this shim keeps old imports working."""
from linkpipe.closed_forms import fourbar, slider_crank  # noqa: F401
