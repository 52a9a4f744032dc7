"""Measure what accuracy costs in time: one scene over a ladder of solver settings.

``python -m linkpipe accuracy configs/x.toml`` (issue 6). Each *row* of the ladder is the scene
with one ``[solver]`` knob (or the sweep's step count) changed, built with
``dataclasses.replace`` on the loaded :class:`~linkpipe.scene.Scene`. Per row:

* wall time, the median of ``repeats`` runs in this one process (so ratios between rows mean
  something): of the stage the knob acts on (``seconds``: positions, derivatives, or the whole
  kinematics for step counts) and of the whole :func:`~linkpipe.pipeline.solve`;
* the max error of position, velocity, acceleration and input force (when the scene has
  effects) against a reference at the same driver values, absolute (scene units) and relative
  (to the mechanism's size for positions, to the largest reference value otherwise);
* Newton iterations (mean, max), failed steps, and whether the assembly branch was kept.

The reference is a closed form (:mod:`linkpipe.closed_forms`) where the scene is a four-bar or
slider-crank, else the tightest setting with extended checks: tolerance 1e-15, analytic
Jacobian, linear derivatives, second-order predictor, then one more Newton step (refinement)
at every step. The input force always comes from that extended run (no closed form for
forces). Every row asks for velocities and accelerations, so all three kinematic orders are
measured even where the scene itself would not compute them.

The knobs ``tol``, ``max_iter``, ``jacobian``, ``derivatives`` and ``predictor`` are varied on
the general Newton path (``method = "newton"``): the closed-form dyads that ``method = "auto"``
takes where the scene decomposes do not iterate. The ``method`` rows compare the paths from the
scene's own settings; a ``dyads`` row the build cannot run says "not available". The Pareto
front (:meth:`Ladder.front`) is found among rows at the scene's own step count, over all paths
and over the Newton path alone.

Modules: :mod:`.knobs` (the settings), :mod:`.references`, :mod:`.timing` (measuring),
:mod:`.rows` (rows, fronts, variables), :mod:`.report` (text and the command); the files are
written by :mod:`linkpipe.stores.accuracy`.
"""
from .knobs import FULL, KNOBS, QUICK, REFERENCE_SOLVER, _all_orders, _with_solver, _with_steps, settings
from .references import Reference, References, _measure_errors, _scales
from .report import header, orders_line, run_accuracy, table
from .rows import QUANTITIES, Ladder, Row
from .timing import measure, method_available

__all__ = ["FULL", "KNOBS", "QUICK", "REFERENCE_SOLVER", "settings", "Reference", "References",
           "header", "orders_line", "run_accuracy", "table", "QUANTITIES", "Ladder", "Row",
           "measure", "method_available", "_all_orders", "_with_solver", "_with_steps",
           "_measure_errors", "_scales"]
