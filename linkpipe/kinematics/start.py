"""The first step: the drawn pose assembled, and carried to the sweep's first driver value."""
from __future__ import annotations

import numpy as np

from ..cache import derived
from ..errors import SceneError
from ..model import Model, constraint_source
from ..model.drive import internal_motion
from .continuation import solve_positions
from .drawing import assembled_drawing, drawn_start
from .linalg import condition, is_singular
from .roots import _null_line_roots, drivers_aligned, newton
from .step import _step_kernels


#: largest driver move per step when the drawn pose is carried to the sweep's first value:
#: 2 degrees for an angle driver, 0.5 % of the mechanism's size for a coordinate driver
CARRY_ANGLE_STEP = np.deg2rad(2.0)


CARRY_LENGTH_STEP = 0.005
#: the longest carry: a drawing farther than this many carry steps from ``from`` is not carried
MAX_CARRY_STEPS = 10_000


class OutOfReach(SceneError):
    """The sweep's first driver value is out of the drawing's reach (one driver): ``along``
    the drivers' values at the drawing, on the sweep's turn, and ``last`` the last values
    assembled on the way from them towards the first (internal units, (nd,))."""

    def __init__(self, *args, along, last):
        super().__init__(*args)
        self.along, self.last = np.asarray(along, float), np.asarray(last, float)


#: the steps a sweep's start may move on to when its first ones are out of reach
REACH_TRIES = 4


def steps_out_of_reach(model: Model, s: np.ndarray, present: np.ndarray, tol_abs: float,
                       max_iter: int) -> tuple[int, str]:
    """``(k, message)``: the sweep's first k steps (of ``s`` (S, nd), those ``present``) are
    out of the drawing's reach, the k-th (or none, k = S) is the first that assembles, and the
    message says so (0, "" where the first present step assembles). Each step that fails gives
    a limit of the reach on its side of the drawing (the last value assembled on the way from
    the drawing towards it: :func:`reach_from_drawing`); the start is then tried at the first
    step within every limit found (an angle measured from the drawing the shorter way round,
    so a later turn counts), :data:`REACH_TRIES` times. Any other failure to assemble stays
    the scene's error."""
    idx = np.flatnonzero(present)
    if not len(idx):
        return 0, ""
    first, message = int(idx[0]), ""
    low, high = -np.inf, np.inf  # the reach, as offsets from the drawing's value
    for _ in range(REACH_TRIES):
        try:
            start_state(model, s[first], tol_abs, max_iter)
            return first, message
        except OutOfReach as exc:
            if not message:
                message = f"[{exc.table}] {exc.key}: {exc.message}; {exc.hint}"
            along, limit = float(exc.along[0]), float(exc.last[0] - exc.along[0])
            if limit > 0:
                high = min(high, limit)
            else:
                low = max(low, limit)
            offset = s[:, 0] - along
            if model.drv_angle[0]:  # the shorter way round from the drawing
                offset = (offset + np.pi) % (2 * np.pi) - np.pi
            with np.errstate(invalid="ignore"):
                near = present & (offset >= low) & (offset <= high)
            if not near.any():
                return len(s), message
            first = int(np.argmax(near))
    start_state(model, s[first], tol_abs, max_iter)  # the scene's own error, if any
    return first, message


def sweep_reach(model: Model) -> tuple[int, str]:
    """:func:`steps_out_of_reach` of ``model``'s own sweep (its drivers' values, the steps
    that have every value), computed once per model: ``preflight``, ``check`` and stage 1
    share it. SceneError where the start cannot be assembled at all."""
    def build(m: Model) -> tuple[int, str]:
        _, s, _, _ = internal_motion(m)
        return steps_out_of_reach(m, s, np.isfinite(s).all(axis=1), m.tolerance(),
                                  m.scene.solver.max_iter)

    return derived(model, "sweep_reach", build)


def start_state(model: Model, s0: np.ndarray, tol_abs: float, max_iter: int):
    """Return (q (n_q,), slope): the assembled start's q and, when the drawn pose was carried
    to ``s0`` by a one-driver path, dq/ds (n_q, 1) along that path's last step (a secant), else
    None. The sweep's first predictor uses it: a sweep that starts on a change point then leaves
    it on the branch the path arrived on instead of on a side chosen by rounding."""
    given = _from_start_pose(model, s0, tol_abs, max_iter)
    if given is not None:
        return given, None
    carried = _carry_drawn_pose(model, s0, tol_abs, max_iter)
    if carried is not None:
        return carried
    return _assemble_directly(model, s0, tol_abs, max_iter), None


def _from_start_pose(model: Model, s0: np.ndarray, tol_abs: float, max_iter: int):
    """q (n_q,) at ``s0`` by Newton from the scene's ``start_pose`` (a pose solved before at
    that driver value: ``follow``'s blocks), or None (none given, or Newton from it fails)."""
    pose = getattr(model.scene, "start_pose", None)
    if pose is None or not model.n_q or not np.isfinite(pose).all():
        return None
    q0 = model.q_of(np.asarray(pose, dtype=float)[None])
    fast = _step_kernels(model)
    q, _, _, conv = (fast.newton(q0[0], s0, tol_abs, max(max_iter, 50)) if fast is not None
                     else newton(model, q0, s0[None], tol_abs, max(max_iter, 50)))
    return q[0] if conv[0] else None


def _assemble_directly(model: Model, s0: np.ndarray, tol_abs: float, max_iter: int) -> np.ndarray:
    """Newton (then least squares) at ``s0`` from the drawing itself; SceneError if impossible."""
    q0 = model.q_of(model.start_position[None])
    fast = _step_kernels(model) if model.n_q else None  # the same Newton on plain floats
    q, res, _, conv = (fast.newton(q0[0], s0, tol_abs, max(max_iter, 50)) if fast is not None
                       else newton(model, q0, s0[None], tol_abs, max(max_iter, 50)))
    if conv[0]:
        return q[0]
    # Newton may wander from a poor guess: a least-squares solve tells whether a solution exists.
    def fun(qq):
        return model.phi(model.positions(qq[None]), s0[None])[0]

    def jac(qq):
        return model.jacobian(model.positions(qq[None]), s0[None])[0]

    from scipy.optimize import least_squares  # here: importing scipy.optimize costs ~0.3 s

    sol = least_squares(fun, q0[0], jac=jac, method="trf", xtol=1e-15, ftol=1e-15, gtol=1e-15,
                        max_nfev=500)
    if np.abs(sol.fun).max() <= tol_abs:
        qq, res2, _, conv2 = newton(model, sol.x[None], s0[None], tol_abs, max_iter)
        if conv2[0]:
            return qq[0]
    path = model.scene.path
    if model.n_q and is_singular(condition(jac(sol.x)[None])[0], model.scene.solver.singular_rcond):
        # stuck on a singular shape (links in line): Newton and least squares cannot leave a
        # mirror-symmetric guess; if either side of it assembles, the guess is just ambiguous
        v, roots = _null_line_roots(model, sol.x[None], s0)
        for t in roots:
            _, _, _, conv3 = newton(model, (sol.x + t * v)[None], s0[None], tol_abs, max_iter)
            if conv3[0]:
                k = int(np.argmax(np.hypot(*v.reshape(-1, 2).T)))
                name = model.point_names[model.moving[k]]
                raise SceneError(path, "points", name,
                                 "the start positions put links in line (a singular "
                                 "configuration), so they do not say which of the mirror-image "
                                 "assemblies is meant",
                                 f"move {name} a little off the line, to the side of the "
                                 "assembly you want")
    worst = float(np.abs(sol.fun).max())
    if worst <= 1e-13 * model.size:
        # assembled to rounding level: it is the tolerance that cannot be met, not the scene
        raise SceneError(path, "solver", "tol",
                         f"tol = {model.scene.solver.tol:g} ({tol_abs:.3g} for this mechanism's "
                         f"size) is below what double precision reaches here: the start "
                         f"assembles to {worst:.3g} and no closer",
                         "use tol >= 1e-15 (a solved step's residual is rounded to about 1e-16 "
                         "of the size)")
    length = dict(model.scene.units).get("length", "length units")
    reach = reach_from_drawing(model, s0, tol_abs, max_iter) if model.n_drivers == 1 else None
    if reach is not None:  # one driver, whose first value the drawing's assembly cannot reach
        along, last = reach
        driver = model.scene.drivers[0]
        scale = np.pi / 180.0 if driver.kind == "angle" else 1.0
        unit = "deg" if driver.kind == "angle" else length
        drawn = model.driver_values_at(model.start_position[None])[0]  # (angles in (-pi, pi])
        first, drawn, along, last = (float(v) / scale for v in (s0[0], drawn[0], along[0], last[0]))
        turn = (f" ({along:.6g} {unit} on the sweep's turn)" if abs(along - drawn) > 1e-9 * max(
            1.0, abs(drawn)) else "")
        raise OutOfReach(path, f'drivers "{driver.name}"', "log" if driver.timed == "log" else "from",
                         f"the first driver value {first:.6g} {unit} is out of reach: from the "
                         f"drawing's {drawn:.6g} {unit}{turn} towards it the mechanism "
                         f"assembles as far as {last:.6g} {unit} and no further",
                         "start the sweep within reach (" + _first_values(model.scene.drivers)
                         + "), or check the link lengths and `local` coordinates",
                         along=reach[0], last=reach[1])
    table, key = constraint_source(model, int(np.argmax(np.abs(sol.fun))))
    where = f"[{table}]" + (f" {key}" if key else "")
    raise SceneError(path, "points", None,
                     f"the start configuration cannot be assembled at the first driver value: "
                     f"at the best fit the constraint of {where} is still off by {worst:.3g} "
                     f"{length} (tolerance {tol_abs:.3g})",
                     "check the link lengths, the `local` coordinates and "
                     + _first_values(model.scene.drivers)
                     + "; the points' x, y must be close to an assembled position")


def reach_from_drawing(model: Model, s0: np.ndarray, tol_abs: float, max_iter: int):
    """``(drawn (nd,), last (nd,))``: the drivers' values at the drawing and the last ones
    assembled on the straight way from them to ``s0`` (angles the shorter way round), in steps
    of at most a quarter of a carry step (at most 4,000), the last step's limit bisected to
    2^-40 of a step; None where the drawing does not
    assemble at its own values or the whole way assembles (the limit is then not the reach)."""
    X = assembled_drawing(model)
    if X is None:
        return None
    delta, n_needed = carry_steps(model, model.start_position[None], s0, model.size)
    delta, n_needed = delta[0], float(n_needed[0])
    if not np.isfinite(n_needed) or n_needed == 0:
        return None
    n = int(min(4000, max(8, 4 * np.ceil(n_needed))))
    path = (s0 - delta) + np.linspace(0.0, 1.0, n + 1)[:, None] * delta
    q, residual, _, _ = solve_positions(model, path, tol=model.scene.solver.tol,
                                        max_iter=max(max_iter, 50), predictor="first",
                                        jacobian="analytic", q_start=model.q_of(X[None])[0],
                                        stop_on_failure=True)
    ok = np.isfinite(q).all(axis=1) & (residual <= tol_abs)
    if ok.all() or not ok[0]:
        return None
    k = int(np.argmin(ok)) - 1
    good, bad, q_good = path[k], path[k + 1], q[k]
    for _ in range(40):  # the limit between the last step that assembles and the first that
        mid = 0.5 * (good + bad)  # does not, by bisection (Newton from the last that does)
        qm, _, _, conv = newton(model, q_good[None], mid[None], tol_abs, max(max_iter, 50))
        if conv[0] and np.isfinite(qm).all():
            good, q_good = mid, qm[0]
        else:
            bad = mid
    return path[0], good


def _first_values(drivers) -> str:
    """Where the drivers' first values come from, as a start-up message's advice names them."""
    logged = [d for d in drivers if d.timed == "log"]
    parts = ["the drivers' `from`"] if len(logged) < len(drivers) else []
    parts += [f'the first value of log column "{d.log[0]}.{d.log[1]}"'
              + (f" (times scale = {d.scale:g})" if d.scale != 1.0 else "") for d in logged]
    return " and ".join(parts)


def _carry_drawn_pose(model: Model, s0: np.ndarray, tol_abs: float, max_iter: int):
    """Return (q (n_q,), slope) at ``s0`` carried by continuation from the drawn pose, or None.

    None when the drawing is within one carrying step of ``s0``, when it cannot be assembled at
    its own driver values, or when the path to ``s0`` leaves the assembly range. ``slope`` as
    :func:`start_state` says (None with several drivers: one path gives one direction only).
    """
    if not model.n_drivers or not model.n_q:
        return None
    delta, n_needed = carry_steps(model, model.start_position[None], s0, model.size)
    delta, n_needed = delta[0], float(n_needed[0])
    if not n_needed <= MAX_CARRY_STEPS:  # far off (or not finite): the direct solve at s0 decides
        return None
    n = int(np.ceil(n_needed))
    if n <= 1:
        return None
    start = s0 - delta  # the drawn values, next to s0 for the angles
    q0 = model.q_of(model.start_position[None])
    fast = _step_kernels(model)
    q_drawn, _, _, conv = (fast.newton(q0[0], start, tol_abs, max(max_iter, 50)) if fast is not None
                           else newton(model, q0, start[None], tol_abs, max(max_iter, 50)))
    if not conv[0] or not drivers_aligned(model, q_drawn, start[None])[0]:
        return None
    path = start + np.linspace(0.0, 1.0, min(n, 2000) + 1)[:, None] * delta
    path[-1] = s0
    # the carry's own settings, not the scene's knobs (a low max_iter or no predictor must not
    # send the start back to the one-jump assembly); it stops at its first failed step
    q, residual, _, _ = solve_positions(model, path, tol=model.scene.solver.tol,
                                        max_iter=max(max_iter, 50), predictor="first",
                                        jacobian="analytic", q_start=q_drawn[0],
                                        stop_on_failure=True)
    if not (np.isfinite(q).all() and (residual <= tol_abs).all()):
        return None  # a step without assembly on the way (or one that did not converge)
    slope = None
    if model.n_drivers == 1:
        slope = ((q[-1] - q[-2]) / (path[-1, 0] - path[-2, 0]))[:, None]
    return q[-1], slope


def carry_steps(model: Model, X0: np.ndarray, s0: np.ndarray, size):
    """``(delta (V, nd), steps (V,))``: how far drawings X0 (V, n_points, 2) of sizes ``size``
    (float or (V,)) are from the driver values s0 (nd,) (angles the shorter way round), and in
    how many carry steps; at most 1 step: the start is assembled at s0 directly."""
    delta = s0 - model.driver_values_at(X0)
    angle = model.drv_angle
    delta[:, angle] = (delta[:, angle] + np.pi) % (2 * np.pi) - np.pi  # the shorter way round
    step = np.where(angle, CARRY_ANGLE_STEP, CARRY_LENGTH_STEP * np.asarray(size)[..., None])
    return delta, np.max(np.abs(delta) / step, axis=-1)


#: a drawing whose assembled pose (at its own driver values) puts a point farther than this
#: fraction of the mechanism's size from where it is drawn is probably not what was meant
#: (shipped scenes: at most 0.006; a `local` coordinate given as a fraction of its link, 0.55)
DRAWING_MOVED_FRACTION = 0.1


def drawing_offset(model: Model) -> tuple[str, float] | None:
    """``(point, distance)``: the moving point that the drawing's own assembly
    (:func:`assembled_drawing`, else, where Newton from the drawing does not reach one,
    damped least squares from it: :func:`_drawing_by_least_squares`) moves farthest, and how
    far (length units); None where the drawing does not assemble at its own driver values."""
    X = assembled_drawing(model)
    if X is None:
        X = _drawing_by_least_squares(model)
    if X is None:
        return None
    moving = model.moving
    moved = np.hypot(*(X[moving] - model.start_position[moving]).T)  # (n_moving,)
    k = int(np.argmax(moved))
    return model.point_names[moving[k]], float(moved[k])


def _drawing_by_least_squares(model: Model) -> np.ndarray | None:
    """The drawing assembled at its own driver values (n_points, 2) by damped least squares
    from the drawn pose (then Newton's polish), for a drawing too far from its assembly for
    Newton's 50 iterations (a wrong length); None where it does not assemble there."""
    from .roots import _lm_root

    start = drawn_start(model)
    if start is None:
        return None
    q0, drawn = start
    tol_abs = model.tolerance()
    q, r, _ = _lm_root(model, q0[0], drawn, tol_abs, max_iter=500)
    if not r <= 10 * tol_abs:
        return None
    q, _, _, conv = newton(model, q[None], drawn[None], tol_abs, 50)
    if not conv[0]:
        return None
    return model.positions(np.asarray(q, dtype=float).reshape(1, -1))[0]


def drawing_slip(model: Model) -> str:
    """``"B assembles 3.55 m from its drawing"`` where the drawing is far from its own assembly
    (:data:`DRAWING_MOVED_FRACTION` of the size; :func:`drawing_offset`), else "": the clause
    ``check``'s and ``run``'s first line carry (``all 61 steps ok — but E assembles 2.1 m from
    its drawing``), before any other line."""
    from ..cache import derived

    def build(m: Model) -> str:
        found = drawing_offset(m)
        if found is None or not found[1] > DRAWING_MOVED_FRACTION * m.size:
            return ""
        length = dict(m.scene.units).get("length", "length units")
        return f"{found[0]} assembles {found[1]:.3g} {length} from its drawing"

    return derived(model, "drawing_slip", build)


def drawing_warnings(model: Model) -> tuple[str, ...]:
    """The warning (one, or none) that the drawn pose is far from an assembled one
    (:data:`DRAWING_MOVED_FRACTION`), computed once per model."""
    return derived(model, "drawing_warnings", _drawing_warnings)


def scene_warnings(model: Model) -> tuple[str, ...]:
    """Everything legal but probably not meant: the scene's own (parsing) and its drawing's."""
    return tuple(model.scene.warnings) + drawing_warnings(model) + far_warnings(model)


def far_warnings(model: Model) -> tuple[str, ...]:
    """A drawing so far from the origin that float64 cannot meet ``[solver] tol`` there (the
    tolerance is floored at what it can: :meth:`Model.tolerance`)."""
    wanted, met = model.scene.solver.tol * model.size, float(model.tolerance())
    if not met > wanted:
        return ()
    length = dict(model.scene.units).get("length", "length units")
    return (f"{model.scene.path}: [points]: the drawing lies {model.extent:.3g} {length} from the "
            f"origin, {model.extent / model.size:.3g} times the mechanism's size: float64 "
            f"resolves positions there to {met:.2g} {length}, above the {wanted:.2g} that "
            f"[solver] tol asks, which the residual is held to instead; put the origin near "
            "the mechanism for full precision",)


def _drawing_warnings(model: Model) -> tuple[str, ...]:
    loose = ([sp.name for sp in model.scene.springs if sp.kind != "gas" and sp.free_length is None]
             if "springs" in model.scene.effects else [])
    if loose and model.n_q and model.n_drivers and assembled_drawing(model) is None:
        names = ", ".join(f'"{n}"' for n in loose)
        return (f"{model.scene.path}: [points]: the drawing does not assemble at the driver "
                "values it itself has, so springs " + names + " measure their start length "
                "(where their preload holds) on the drawing as written, which may be a guess; "
                "draw the points nearer an assembled pose, or give free_length",)
    if not drawing_slip(model):
        return ()
    name, distance = drawing_offset(model)
    length = dict(model.scene.units).get("length", "length units")
    start = ("the sweep starts from that pose" if assembled_drawing(model) is not None else
             "Newton from the drawing does not reach it, so the sweep's start is assembled at "
             "its first driver values directly")
    return (f"{model.scene.path}: [points] {name}: the drawing is not an assembled pose: "
            f"assembled at the drivers' drawn values, {name} lands {distance:.3g} {length} "
            f"from where it is drawn ({100 * distance / model.size:.0f} % of the mechanism's "
            f"size), and {start}; check the link lengths, `local` "
            "coordinates and sides, or draw the points nearer the pose you mean",)
