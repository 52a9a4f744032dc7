"""Stage 1: solve a mechanism over its whole sweep (positions, velocities, accelerations).

The paths (``[solver] method``: "auto" takes the closed-form dyads where the scene decomposes
and every dyad stays clear of its singular shape, else the vectorised Newton path) are chosen
in one place, :mod:`.plan` (:data:`METHODS`, :class:`Plan`: the positions of any steps of a
sweep, switching itself from the dyads to Newton where auto must leave them); the pipeline's
stage 1 (:class:`linkpipe.stage1.Stage1`) asks a Plan segment by segment, :func:`solve_sweep`
over a sweep of driver values alone (the benchmarks' kernel). Modules:
:mod:`.dyads` (closed-form fast path), :mod:`.vectorised` (coarse continuation + batched
Newton), :mod:`.continuation` (step by step), :mod:`.start` (the first step), :mod:`.roots`
(Newton and the rescues), :mod:`.step` (one-step float kernels), :mod:`.linalg` (sparse and
dense solves, condition), :mod:`.rates` (velocities, accelerations, link rates), :mod:`.angles`
(link angles unwrapped), :mod:`.drawing` (the drawing assembled).
"""
from __future__ import annotations

from .decompose import decompose
from .plan import (DYADS_LEFT, METHODS, Method, Plan, Sweep, beyond_reach, dyad_plan,
                   dyad_sweep, solve_sweep, solve_with_newton, start_branches)
from .start import OutOfReach, start_state, steps_out_of_reach, sweep_reach

from .pivots import solve_pivot_variants  # noqa: E402
from .angles import AngleCarry, link_angles_unwrapped, link_rates  # noqa: E402
from .rates import dense_chunk, dense_derivatives, derivatives, fd_derivatives  # noqa: E402
from ..model.drive import internal_motion as driver_motion  # noqa: E402
from .roots import newton  # noqa: E402
from .continuation import solve_positions  # noqa: E402
from .sparse_lu import SPARSE_FROM, linear_algebra_used  # noqa: E402

__all__ = ["solve_sweep", "beyond_reach", "METHODS", "OutOfReach", "steps_out_of_reach", "sweep_reach", "AngleCarry", "dyad_plan", "dyad_sweep", "DYADS_LEFT", "solve_pivot_variants", "start_branches", "Sweep", "Plan", "Method", "solve_with_newton", "decompose",
           "start_state", "derivatives", "dense_derivatives", "driver_motion", "fd_derivatives",
           "link_angles_unwrapped", "link_rates", "newton", "solve_positions", "linear_algebra_used",
           "dense_chunk", "SPARSE_FROM"]
