"""The drivers' own forces over time: constant, a law, a log column, or none (free).

Values are generalized forces in the drivers' internal units: a torque per radian for an angle
driver, a force for a distance or coordinate driver (the scene's force and length units). A
log column is ``column x unit_factor x scale + offset`` (:meth:`DynamicsTables.force_log
<linkpipe.scene.dynamics.DynamicsTables.force_log>`), read at the true instants (the log's
stamps less its ``lag``)."""
from __future__ import annotations

import numpy as np

from ..log_splines import log_spline
from ..model.drive import LAWS


class Forcing:
    """``at(t)`` -> (nd,) the drivers' forces at time ``t`` (s)."""

    def __init__(self, scene):
        logs = {log.name: log for log in scene.logs}
        self.parts = []
        for d in scene.drivers:
            if d.force is not None:
                self.parts.append(("constant", float(d.force)))
            elif d.force_law is not None:
                self.parts.append(("law", d.force_law))
            elif d.force_log is not None:
                log = logs[d.force_log[0]]
                # the column in the scene's units (force, or force per area), x scale + offset
                values = log.columns[d.force_log[1]] * (d.unit_factor * d.scale) + d.offset
                self.parts.append(("log", log_spline(log.t, values, 0.0)))
            else:
                self.parts.append(("free", 0.0))

    def at(self, t: float) -> np.ndarray:
        return self.over(np.array([float(t)]))[0]

    def over(self, t: np.ndarray) -> np.ndarray:
        """(S, nd) at the instants ``t`` (S,): each driver's force over all instants at once."""
        t = np.asarray(t, dtype=float)
        out = np.empty((len(t), len(self.parts)))
        for j, (kind, how) in enumerate(self.parts):  # a few drivers: the columns
            if kind == "law":
                tau = np.clip(t / how.duration, 0.0, 1.0)
                out[:, j] = how.from_value + (how.to_value - how.from_value) * LAWS[how.law][0](tau)
            elif kind == "log":
                out[:, j] = how(t)
            else:
                out[:, j] = how
        return out
