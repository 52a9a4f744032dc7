"""The scene as frozen, typed objects: what a TOML scene file means once it is read.

The contract is ``docs/scene-format.md``. Every check that needs only the text lives here;
checks that need the constraint Jacobian (degrees of freedom, assembly of the start
configuration) live in :mod:`linkpipe.model` and raise the same :class:`SceneError`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


EFFECTS = ("springs", "gravity", "inertia", "damping", "loads", "friction")
#: ``[[springs]] kind`` (first = default); "ground" as a torsion spring's second link
SPRING_KINDS = ("linear", "tension_only", "compression_only", "gas")
GROUND = "ground"
KINEMATIC_ORDERS = ("velocity", "acceleration")


@dataclass(frozen=True)
class Point:
    name: str
    x: float
    y: float
    fixed: bool = False


@dataclass(frozen=True)
class Link:
    """A rigid body. ``points[0]``, ``points[1]`` span its frame.

    ``length``: the exact distance of the first two points from ``lengths``, or None (take it
    from the start configuration). ``local``: explicit local coordinates ``{name: (u, v)}`` of
    further points (others are taken from the start configuration), those placed by two
    side lengths included. ``distances``: the side lengths that placed further points,
    ``{(earlier point, later point): (key, d)}`` as ``lengths`` gives them, and ``side`` {point:
    "left" | "right"} where given (:mod:`.sides`: a study's variants place them again).
    """

    name: str
    points: tuple[str, ...]
    length: float | None = None
    local: dict[str, tuple[float, float]] = field(default_factory=dict)
    distances: dict[tuple[str, str], tuple[str, float]] = field(default_factory=dict)
    side: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Slider:
    """A point on a line: fixed (``through`` + ``direction``) or through two points of a link."""

    name: str
    point: str
    through: tuple[float, float] | None = None
    direction: tuple[float, float] | None = None
    line_points: tuple[str, str] | None = None  # along = ["D", "E"]

    @property
    def moving(self) -> bool:
        return self.line_points is not None


@dataclass(frozen=True)
class Input:
    """Where the actuator pushes: a moving point and a direction, global or, with ``link``, in
    that link's frame (u along its first two points, v to their left), turning with it."""

    point: str
    direction: tuple[float, float]
    link: str | None = None


@dataclass(frozen=True)
class Driver:
    """One driven coordinate.

    ``kind`` is ``"angle"`` (``points`` = (a, b): direction of a->b, degrees from +x, CCW; with
    ``relative_to`` = (c, d): measured CCW from the direction of c->d instead), ``"distance"``
    (``points`` = (a, b): their distance, a linear actuator) or ``"coordinate"`` (``points`` =
    (p,), ``axis`` 0 for x, 1 for y). ``bodies``: for a relative angle, the links carrying
    the two vectors (the second may be ``"ground"``). ``steps`` is the resolved
    number of steps; ``step`` is the step size when the scene gave ``step`` (values are then
    ``from + i*step``), else None (values ``from + i*(to-from)/(steps-1)``).
    ``rate`` and ``acceleration`` in driver units per s and s^2 (degrees for angles).

    In a scene with ``[time]`` (:class:`TimeSweep`) the value is a function of time: ``law``
    (one of :data:`LAWS`, from ``from_value`` to ``to_value`` over the sweep), ``rate`` and
    ``acceleration`` (``from + rate t + acceleration t^2/2``; ``to_value`` is then that value at
    the last instant), or ``log`` = (log name, column) times ``scale`` through a spline with
    ``smoothing`` (``from_value``/``to_value``: the smallest and largest finite value the
    log gives, which sets a distance row's scale). ``steps`` is then the number of instants.
    """

    name: str
    kind: str
    points: tuple[str, ...]
    axis: int | None
    from_value: float
    to_value: float
    steps: int
    step: float | None = None
    rate: float = 0.0
    acceleration: float = 0.0
    input: Input | None = None
    relative_to: tuple[str, str] | None = None
    bodies: tuple[str, str] | None = None
    law: str | None = None
    log: tuple[str, str] | None = None
    scale: float = 1.0
    smoothing: float = 0.0
    timed: str | None = None  # in a [time] scene: "law", "log" or "rate"; None in a v1 sweep
    #: (shortest, longest) value the actuator reaches, in the driver's units (version 3), or None
    stroke: tuple[float, float] | None = None
    #: a log driver's value is ``column x unit_factor x scale + offset`` (``unit_factor``: the
    #: column's ``[[logs]] units`` in the driver's units, 1 without)
    offset: float = 0.0
    unit_factor: float = 1.0
    #: with [dynamics]: the start velocity (driver units per second) and the actuator's
    #: generalized force: a constant ``force``, a ``force_law`` or a ``force_log`` (log, column)
    #: times ``scale``; all None: free (no actuator force)
    start_rate: float = 0.0
    force: float | None = None
    force_law: "ForceLaw | None" = None
    force_log: tuple[str, str] | None = None

    @property
    def free(self) -> bool:
        """With [dynamics]: no actuator force on this driver."""
        return self.force is None and self.force_law is None and self.force_log is None

    @property
    def is_angle(self) -> bool:
        """Whether the driven value is an angle (degrees in the file, radians inside)."""
        return self.kind == "angle"


@dataclass(frozen=True)
class ForceLaw:
    """``force_law``: the force goes from ``from_value`` to ``to_value`` by ``law`` (one of
    :data:`LAWS`) over the first ``duration`` seconds of [dynamics], then stays at ``to_value``."""

    law: str
    from_value: float
    to_value: float
    duration: float


@dataclass(frozen=True)
class Dynamics:
    """``[dynamics]``: integrate from 0 to ``to`` s, the motion stored at ``instants`` (S,)
    = 0, output_step, ... (``to`` itself where it lands within 1e-9 of a step), the
    integrator's relative tolerance ``rtol`` and ``method`` (:data:`DYNAMICS_METHODS`)."""

    to: float
    output_step: float
    rtol: float
    method: str = "DOP853"
    instants: np.ndarray = field(default=None, compare=False, repr=False)


#: the integrators of ``[dynamics] method`` (scipy.integrate.solve_ivp's names; first = default)
DYNAMICS_METHODS = ("DOP853", "Radau")


#: the motion laws of ``[[drivers]] law`` (value = from + (to - from) f(tau) over [time])
LAWS = ("linear", "harmonic", "cycloidal", "polynomial345")


@dataclass(frozen=True)
class LogData:
    """One ``[[logs]]`` entry, read and checked: ``name``, ``file`` as written, ``path`` the
    file it resolved to, ``time`` the time column's name, ``t`` (rows,) its values (finite,
    strictly increasing), ``columns`` {name: (rows,) float} the numeric columns drivers use
    (NaN where the log has no value), ``names`` every column of the file."""

    name: str
    file: str
    path: str
    time: str
    t: np.ndarray = field(compare=False, repr=False)
    columns: dict[str, np.ndarray] = field(compare=False, repr=False)
    names: tuple[str, ...] = ()
    #: ``t`` is the true instants, ``t_logged - lag`` (s); ``units`` {column: (quantity, order,
    #: SI value of its unit)} from ``[[logs]] units`` (:func:`~.units.column_unit`)
    lag: float = 0.0
    units: dict = field(default_factory=dict, compare=False, repr=False)


@dataclass(frozen=True)
class Measurement:
    """A logged signal beside its computed counterpart: ``values`` (S,) at the scene's steps,
    ``sum(column_i x scale_i) + offset`` over ``columns`` ((log, column), ...) after their
    units (NaN where a log has none; a log other than [time]'s read through its spline at the
    instants); ``log``, ``column``, ``scale`` the first column's; ``of`` the computed series
    ``(variable, name, axis)`` (axis 0/1 for an xy variable, else None); ``sigma`` its standard
    deviation (None: not given)."""

    name: str
    log: str
    column: str
    scale: float
    of: tuple
    sigma: float | None = None
    values: np.ndarray = field(default=None, compare=False, repr=False)
    columns: tuple = ()
    scales: tuple = ()
    offset: float = 0.0
    #: (S, n) each column in the scene's units at the steps: ``values = parts @ scales + offset``
    parts: np.ndarray = field(default=None, compare=False, repr=False)
    alarm: float | None = None  # follow: a residual beyond alarm x sigma is an alarm

    @property
    def address(self) -> str:
        variable, name, axis = self.of
        return f"{variable}.{name}" + ("" if axis is None else f".{'xy'[axis]}")


@dataclass(frozen=True)
class TimeSweep:
    """``[time]``: the steps are the ``instants`` (S,) in seconds: ``from + i (to - from)/(steps
    - 1)`` (or ``from + i step``), or the rows of the log named ``log``."""

    from_value: float
    to_value: float
    steps: int
    step: float | None = None
    log: str | None = None
    instants: np.ndarray = field(default=None, compare=False, repr=False)


#: Choices of the [solver] knobs that trade accuracy for speed (first = default).
SOLVER_CHOICES = {
    "jacobian": ("analytic", "finite_difference"),
    "derivatives": ("linear", "finite_difference"),
    "predictor": ("first", "second", "none"),
    "method": ("auto", "newton", "dyads"),
    "linear_algebra": ("auto", "dense", "sparse"),
}


@dataclass(frozen=True)
class Solver:
    """Settings of stage 1. ``tol`` is relative to the mechanism's size.

    ``jacobian``: analytic or finite-difference Newton Jacobian. ``derivatives``: velocities and
    accelerations by linear solves or by finite differences of positions along the sweep.
    ``predictor``: start guess of each step (none / first order / second order).
    ``method``: ``auto`` (closed-form dyads where the scene decomposes, else Newton),
    ``newton`` (always the general path) or ``dyads`` (require the fast path).
    ``singular_rcond``: 1/condition below which a step's Jacobian counts as singular. At a
    change point or assembly limit even a fully converged solution has a smallest singular value
    of about sqrt(machine eps) ~ 1e-8 (the root is double), so values much below 1e-6 stop
    flagging exact singular configurations.
    ``linear_algebra``: the one-step work of the general path (sequential continuation, start)
    on dense Jacobians (``dense``), on a sparse LU (``sparse``), or by size (``auto``: sparse
    from :data:`linkpipe.kinematics.sparse_lu.SPARSE_FROM` unknowns).
    ``rate_residuals``: also store each step's velocities and accelerations put back into
    their linear equations (``velocity_residual``, ``acceleration_residual``), a run-time
    re-check of what the tests prove (rounding level); off by default, it doubles the
    Jacobian stage.
    """

    tol: float = 1e-12
    max_iter: int = 25
    jacobian: str = "analytic"
    derivatives: str = "linear"
    predictor: str = "first"
    method: str = "auto"
    singular_rcond: float = 1e-6
    linear_algebra: str = "auto"
    rate_residuals: bool = False
    #: friction's sign(v) is tanh(v / scale): a speed in length units per second (angular rates
    #: use it divided by the mechanism's size); None: 1e-6 of the mechanism's size per second
    friction_velocity_scale: float | None = None


@dataclass(frozen=True)
class Spring:
    """A spring between two points. ``kind`` (:data:`SPRING_KINDS`): ``linear`` tension
    ``k (length - free_length)`` (or ``preload`` at the start); ``tension_only`` and
    ``compression_only`` the same law where it pulls (a cable) or pushes, else 0; ``gas``
    tension ``-force_extended ((extended_length - dead_length) / (length - dead_length))**gamma``
    (k = 0 and no free length). ``damping`` applies to every kind."""

    name: str
    between: tuple[str, str]
    k: float
    free_length: float | None = None
    preload: float | None = None
    damping: float = 0.0
    kind: str = "linear"
    force_extended: float | None = None
    extended_length: float | None = None
    dead_length: float | None = None
    gamma: float = 1.0
    #: a gas spring's shortest length (version 3; its longest is extended_length), or None
    compressed_length: float | None = None


@dataclass(frozen=True)
class Friction:
    """One ``[[friction]]`` entry (version 3). ``kind``: ``"pins"`` (``joints``: point names;
    a torque ``mu pin_radius |pin force| + viscous w_rel`` at every body pair meeting at each),
    ``"slider"`` (``slider``: its name; ``mu |normal force| + viscous v``) or ``"driver"``
    (``driver``: its name; seal friction ``coulomb`` (+ Stribeck ``stribeck_peak`` at
    ``stribeck_velocity``) + ``viscous`` rate)."""

    name: str
    kind: str
    joints: tuple[str, ...] = ()
    slider: str | None = None
    driver: str | None = None
    mu: float = 0.0
    pin_radius: float = 0.0
    viscous: float = 0.0
    coulomb: float = 0.0
    stribeck_peak: float | None = None
    stribeck_velocity: float | None = None


@dataclass(frozen=True)
class TorsionSpring:
    """A torsion spring: angle = direction of ``links[0]``'s u axis minus ``links[1]``'s
    (``"ground"``: 0); torque ``k (angle - free_angle)`` turns the second link CCW and the first
    CW. ``k`` per radian, ``free_angle`` in degrees as written."""

    name: str
    links: tuple[str, str]
    k: float
    free_angle: float


@dataclass(frozen=True)
class Mass:
    link: str
    mass: float
    center: str | tuple[float, float]
    inertia: float = 0.0


@dataclass(frozen=True)
class Load:
    """A constant force at a point (global frame) or a couple on a link (CCW positive)."""

    name: str
    point: str | None = None
    force: tuple[float, float] | None = None
    link: str | None = None
    torque: float | None = None


@dataclass(frozen=True)
class Outputs:
    kinematics: tuple[str, ...] = ()
    trace: tuple[str, ...] = ()
    vectors: tuple[str, ...] = ()


@dataclass(frozen=True)
class Scene:
    """A whole checked scene. ``text`` is the TOML source, ``path`` where it came from."""

    path: str
    text: str
    name: str
    description: str
    units: dict[str, str]
    points: tuple[Point, ...]
    links: tuple[Link, ...]
    sliders: tuple[Slider, ...]
    drivers: tuple[Driver, ...]
    solver: Solver
    effects: tuple[str, ...] = ()
    gravity: tuple[float, float] | None = None
    springs: tuple[Spring, ...] = ()
    masses: tuple[Mass, ...] = ()
    loads: tuple[Load, ...] = ()
    outputs: Outputs = Outputs()
    warnings: tuple[str, ...] = ()  # legal but probably not meant (the summary prints them)
    torsion_springs: tuple[TorsionSpring, ...] = ()
    time: TimeSweep | None = None
    logs: tuple[LogData, ...] = ()
    measurements: tuple["Measurement", ...] = ()
    friction: tuple[Friction, ...] = ()
    dynamics: Dynamics | None = None
    #: (n_points, 2) a pose solved before at the sweep's first driver value, where the start
    #: is assembled from instead of carried from the drawing (follow's blocks: the pose of the
    #: row their window starts at); None: from the drawing. Not a scene key
    start_pose: np.ndarray | None = field(default=None, compare=False, repr=False)

    @property
    def point_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.points)

    @property
    def n_steps(self) -> int:
        return self.drivers[0].steps if self.drivers else 1

    @property
    def present_but_off(self) -> tuple[str, ...]:
        """Effect tables present in the file but not named in ``effects`` (validated, unused)."""
        present = {
            "springs": bool(self.springs or self.torsion_springs),
            "gravity": self.gravity is not None,
            "inertia": bool(self.masses),
            "loads": bool(self.loads),
            "damping": any(s.damping for s in self.springs),
            "friction": bool(self.friction),
        }
        return tuple(e for e in EFFECTS if present[e] and e not in self.effects)


