"""Friction (version 3): at pins (a friction circle), at sliders and in actuators' seals.

Every law opposes a relative motion ``v`` with ``sign(v)`` regularised as ``tanh(v / v_s)``
(``[solver] friction_velocity_scale``: a step at rest has no friction, never a NaN):

* an actuator's seal (``driver``): a force (torque) on the driver's own value,
  ``(coulomb + (peak - coulomb) exp(-(v / velocity)^2)) sign(v) + viscous v`` with ``v`` the
  driver's rate. It is a generalized force on the driver alone: in the mechanism's coordinates
  ``Q = (f / Phi_s) dPhi_d/dX`` at the driver's points, so it changes the actuator's force and
  nothing else (the multipliers of every other row stay as they were);
* a slider (``slider``): ``mu |N| sign(v) + viscous v`` along the guide at the slider's point
  (and the opposite at the moving guide's first point), ``N`` the guide's normal force on the
  point, ``v`` the sliding speed along the guide;
* pins (``joints``): at every pair of bodies meeting at a pin, a couple
  ``mu r |F| sign(w) + viscous w`` with ``w`` the second body's angular velocity relative to
  the first's, on the second body (minus) and the first (plus); ``F`` the force between them:
  the pin's force on the moving body where the other is ground, else half the difference of
  the pin's forces on the two (which is each one's force where no load acts at the pin).

Slider and pin friction depend on the forces they change. Those forces are linear in the
friction's couples and guide forces, so each is solved once per unit load (one Lagrange solve
per link with a pin friction and per slider with friction: :func:`coupled`), and the magnitudes
are then iterated per step on those small arrays to ``[solver] tol`` (``max_iter`` rounds;
a step that does not converge is ``not_converged``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model import Model
from ..model import equations as eq
from ..output_units import common_unit, friction_units
from .applied import Applied, couple_as_body, merge_bodies
from .lagrange import body_rows, joints, motor_terms

#: a friction's sign: tanh(v / scale), the default scale this part of the mechanism's size per s
DEFAULT_VELOCITY_SCALE = 1e-6


def velocity_scale(model: Model, size=None):
    """The speed (length units per second) where the regularised sign reaches tanh(1)."""
    given = model.scene.solver.friction_velocity_scale
    size = model.size if size is None else size
    return DEFAULT_VELOCITY_SCALE * size if given is None else given


def smooth_sign(v, scale):
    """``tanh(v / scale)``: sign(v) away from rest, 0 at rest, smooth in between."""
    return np.tanh(v / scale)


def seal_law(entry, v, scale):
    """The seal's signed friction (S,) at rates ``v`` (S,): positive opposes a positive rate."""
    level = entry.coulomb
    if entry.stribeck_peak is not None:
        breakaway = entry.stribeck_peak - entry.coulomb
        level = level + breakaway * np.exp(-(v / entry.stribeck_velocity) ** 2)
    return level * smooth_sign(v, scale) + entry.viscous * v


def link_angular_velocity(model: Model, X, V, links=None):
    """(S, n_links) rad/s: each link's from its first two points' velocities (``links``: only
    those link indices, in that order)."""
    a, b = (model.link_a, model.link_b) if links is None else (model.link_a[list(links)],
                                                               model.link_b[list(links)])
    out = np.empty((X.shape[0], len(a)))
    for j, (pa, pb) in enumerate(zip(a, b)):  # link by link on columns (no gathered copies)
        dx, dy = X[:, pb, 0] - X[:, pa, 0], X[:, pb, 1] - X[:, pa, 1]
        dvx, dvy = V[:, pb, 0] - V[:, pa, 0], V[:, pb, 1] - V[:, pa, 1]
        out[:, j] = (dx * dvy - dy * dvx) / (dx * dx + dy * dy)
    return out


@dataclass(frozen=True)
class Layout:
    """Where the scene's friction acts. ``pairs``: (entry, point, first body, second body) of
    every body pair at every friction pin, bodies as link indices (-1: ground); ``slides``:
    (entry, slider index, point, guide's first point or -1, slider row); ``seals``: (entry,
    driver index); ``links``: the links a pin friction turns (one response each)."""

    pairs: tuple
    slides: tuple
    seals: tuple
    links: tuple

    @classmethod
    def of(cls, model: Model) -> "Layout":
        scene, names = model.scene, model.point_names
        with_rows = {li for li, _ in joints(model)}
        pairs, slides, seals = [], [], []
        first = len(model.dist_a) + 2 * len(model.loc_a)
        fixed_i = [i for i, x in enumerate(scene.sliders) if not x.moving]
        moving_i = [i for i, x in enumerate(scene.sliders) if x.moving]
        row_of = {i: first + k for k, i in enumerate(fixed_i + moving_i)}
        drivers = [d.name for d in scene.drivers]
        for e, fr in enumerate(scene.friction):
            if fr.kind == "pins":
                for name in fr.joints:
                    p = names.index(name)
                    bodies = ([-1] if model.fixed[p] else []) + [
                        li for li, ln in enumerate(scene.links)
                        if name in ln.points and li in with_rows]
                    pairs += [(e, p, bodies[i], bodies[j]) for i in range(len(bodies))
                              for j in range(i + 1, len(bodies))]
            elif fr.kind == "slider":
                i = [s.name for s in scene.sliders].index(fr.slider)
                sl = scene.sliders[i]
                d = names.index(sl.line_points[0]) if sl.moving else -1
                slides.append((e, i, names.index(sl.point), d, row_of[i]))
            else:
                seals.append((e, drivers.index(fr.driver)))
        links = tuple(sorted({b for _, _, i, j in pairs for b in (i, j) if b >= 0}))
        return cls(tuple(pairs), tuple(slides), tuple(seals), links)

    @property
    def coupled(self) -> bool:
        """Whether some friction depends on the forces it changes (pins, sliders)."""
        return bool(self.pairs or self.slides)


def seal_loads(ctx, layout: Layout, phi_s) -> tuple:
    """The seals' signed friction (S, n_seals) and its loads: ``(Applied, bodies)``, the
    point forces ``(f / Phi_s) dPhi_d/dX`` at each driver's points (virtual work ``-f ds``)
    and, for a driver whose row acts on bodies (an angle on one link, a relative angle), each body's part."""
    model, X = ctx.model, ctx.position
    scale = velocity_scale(model, ctx.constants.size)
    points, bodies = ctx.zeros_points(), {}
    signed = np.zeros((ctx.n_steps, len(layout.seals)))
    if not layout.seals:
        return signed, Applied(points, ctx.zeros_links()), bodies
    rows = (ctx.constants.model_rows or model.rows).drivers
    row_link = body_rows(model)
    xy = lambda p: (X[:, p, 0], X[:, p, 1])  # noqa: E731
    lam = np.zeros((ctx.n_steps, model.n_rows))
    for c, (e, j) in enumerate(layout.seals):
        size = ctx.constants.size if model.scene.drivers[j].is_angle else 1.0
        signed[:, c] = seal_law(model.scene.friction[e], ctx.motion.s_dot[:, j], scale / size)
        r = model.n_constraints + j
        with np.errstate(invalid="ignore", divide="ignore"):
            per = signed[:, c] / phi_s[:, j]  # Q = per dPhi_d/dX: virtual work -signed per ds
        per = np.where(np.isfinite(per), per, 0.0)
        s = ctx.motion.s[:, j]
        for _, p, gx, gy in eq.driver_jacobian_terms(rows[j], r, xy, np.cos(s), np.sin(s)):
            points[:, p, 0] += per * gx
            points[:, p, 1] += per * gy
            if model.drv_kind[j] == eq.ANGLE and row_link[r] >= 0:  # on that body: its -Q_k
                body = bodies.setdefault(int(row_link[r]), {})
                merge_bodies(body, {p: np.stack([-per * gx, -per * gy], axis=1)})
        if model.drv_kind[j] == eq.RELATIVE:
            lam[:, r] = -per
    if (model.drv_kind == eq.RELATIVE).any() and lam.any():
        for li, body in motor_terms(model, X, ctx.motion.s, lam,
                                    ctx.constants.model_rows).items():
            merge_bodies(bodies.setdefault(li, {}), body)
    return signed, Applied(points, ctx.zeros_links()), bodies


def unit_loads(ctx, layout: Layout, influence, Xz):
    """The unknowns' unit loads, one per response: a unit couple (CCW) on each link of
    ``layout.links`` (as its force pair on the link's first two points), then a unit force
    along each friction slider's guide (on its point, minus on the moving guide's first point).
    Yields ``(Q at every point (S, P, 2), its virtual work per driver (S, nd), bodies)``."""
    for forces, work, bodies in unit_load_terms(ctx, layout, influence, Xz):
        points = ctx.zeros_points()
        for p, f in forces:
            points[:, p] += f
        yield points, work, bodies


def unit_load_terms(ctx, layout: Layout, influence, Xz):
    """:func:`unit_loads` as the few points they load: yields ``(((point, (S, 2) force), ...),
    virtual work (S, nd), bodies)``; a point's total is the sum of its forces in this order."""
    model = ctx.model
    for li in layout.links:
        body = couple_as_body(model, np.ones(ctx.n_steps), li, Xz)  # {b: f, a: -f}
        yield tuple(body.items()), influence.link_angles[:, li, :], \
            {li: merge_bodies({}, body, -1.0)}
    for _, _, p, d, _ in layout.slides:
        t = guide_direction(ctx, layout, p, d, Xz)
        forces = [(p, t)]
        work = np.einsum("sx,sxd->sd", t, influence.points[:, p])
        if d >= 0:
            forces.append((d, -t))
            work = work - np.einsum("sx,sxd->sd", t, influence.points[:, d])
        yield tuple(forces), work, {}


def guide_direction(ctx, layout, p, d, Xz):
    """(S, 2) the unit direction of the guide of the slider at point ``p`` (moving guide: from
    its first point ``d`` to its second)."""
    scene, names = ctx.model.scene, ctx.model.point_names
    sl = next(s for s in scene.sliders if names.index(s.point) == p
              and (d < 0 or names.index(s.line_points[0]) == d))
    if d < 0:
        n = np.asarray(sl.direction, float)
        return np.broadcast_to(n / np.hypot(*n), (ctx.n_steps, 2))
    e = names.index(sl.line_points[1])
    t = Xz[:, e] - Xz[:, d]
    with np.errstate(invalid="ignore", divide="ignore"):
        return t / np.hypot(t[:, 0], t[:, 1])[:, None]


@dataclass
class Rates:
    """The relative motions friction opposes: ``pairs`` (S, n_pairs) rad/s (second body minus
    first), ``slides`` (S, n_slides) along each guide."""

    pairs: np.ndarray
    slides: np.ndarray

    @classmethod
    def of(cls, ctx, layout: Layout, Xz) -> "Rates":
        """The rates at every step (0 where the velocities are not finite), of the links and
        points friction acts on alone."""
        V = ctx.velocity
        w = link_angular_velocity(ctx.model, Xz, V, layout.links)  # (S, len(layout.links))
        w = np.where(np.isfinite(w), w, 0.0)
        w = np.concatenate([w, np.zeros((ctx.n_steps, 1))], axis=1)  # index -1: ground
        at = {li: k for k, li in enumerate(layout.links)}
        at[-1] = -1
        pairs = np.stack([w[:, at[j]] - w[:, at[i]] for _, _, i, j in layout.pairs], axis=1) \
            if layout.pairs else np.zeros((ctx.n_steps, 0))
        slides = np.zeros((ctx.n_steps, len(layout.slides)))
        finite = lambda q: np.where(np.isfinite(V[:, q]), V[:, q], 0.0)  # noqa: E731
        for c, (_, _, p, d, _) in enumerate(layout.slides):
            t = guide_direction(ctx, layout, p, d, Xz)
            rel = finite(p) - (finite(d) if d >= 0 else 0.0)
            slides[:, c] = rel[:, 0] * t[:, 0] + rel[:, 1] * t[:, 1]
        return cls(pairs, slides)


def pair_forces(layout: Layout, pin_index: dict, pins):
    """(n_pairs, 2, ...) the force between each pair's bodies from the pins' forces on bodies
    ``pins`` (n_joints, 2, ...), pin first (the step axis last: each row one contiguous block
    where the pins are laid out so): the moving body's where the other is ground, else half
    the difference (second minus first)."""
    if not layout.pairs:
        return np.zeros((0,) + pins.shape[1:])
    out = np.empty((len(layout.pairs),) + pins.shape[1:])
    for c, (_, p, i, j) in enumerate(layout.pairs):  # row by row: no gathered temporaries
        if i < 0:
            out[c] = pins[pin_index[(j, p)]]
        else:
            np.subtract(pins[pin_index[(j, p)]], pins[pin_index[(i, p)]], out=out[c])
            out[c] *= 0.5
    return out


def normal_forces(ctx, layout: Layout, lam, Xz):
    """(n_slides, 2, ...) each friction slider's normal force on its point: its row's
    multiplier times that row's gradient there (``lam`` (n_rows, ..., S), row first)."""
    if not layout.slides:
        return np.zeros((0, 2) + lam.shape[1:])
    model = ctx.model
    want = {(r, p) for _, _, p, _, r in layout.slides}
    grads = {}
    for r, p, gx, gy in model.jacobian_terms(Xz, ctx.motion.s, ctx.constants.model_rows):
        if (r, p) in want:
            g = grads.get((r, p), (0.0, 0.0))
            grads[(r, p)] = (g[0] + gx, g[1] + gy)
    out = np.empty((len(layout.slides), 2) + lam.shape[1:])
    for c, (_, _, p, _, r) in enumerate(layout.slides):
        gx, gy = grads[(r, p)]
        np.multiply(lam[r], gx, out=out[c, 0])
        np.multiply(lam[r], gy, out=out[c, 1])
    return out


def solve_magnitudes(ctx, layout: Layout, rates: Rates, base_pairs, base_normals, resp_pairs,
                     resp_normals, ok):
    """Iterate the pins' couples and the sliders' forces to ``[solver] tol`` at every step.

    ``base_pairs`` (n_pairs, 2, S), ``base_normals`` (n_slides, 2, S): the forces without these
    frictions; ``resp_*`` (n_pairs or n_slides, 2, K, S): their change per unit of each of the
    K unknowns (link couples, then slider forces); the step axis last throughout, so every
    operation of a round is on contiguous rows of steps. Returns (pair torques (S, n_pairs)
    and slider forces (S, n_slides), signed: positive opposes a positive relative rate; link
    couples (S, n_links of layout.links); converged (S,) bool)."""
    model, scene = ctx.model, ctx.model.scene
    scale = velocity_scale(model, ctx.constants.size)
    n_links = len(layout.links)
    slot = {li: k for k, li in enumerate(layout.links)}
    A = np.zeros((len(layout.pairs), n_links))  # link couples = A @ pair torques
    for c, (_, _, i, j) in enumerate(layout.pairs):
        A[c, slot[j]] -= 1.0  # the second body: the torque opposing its relative rotation
        if i >= 0:
            A[c, slot[i]] += 1.0
    mu_r = np.array([scene.friction[e].mu * scene.friction[e].pin_radius for e, *_ in layout.pairs])
    c_pair = np.array([scene.friction[e].viscous for e, *_ in layout.pairs])
    mu_s = np.array([scene.friction[e].mu for e, *_ in layout.slides])
    c_slide = np.array([scene.friction[e].viscous for e, *_ in layout.slides])
    size = ctx.constants.size
    sgn_pair = smooth_sign(rates.pairs, _column(scale / size))
    sgn_slide = smooth_sign(rates.slides, _column(scale))
    visc_pair, visc_slide = c_pair * rates.pairs, c_slide * rates.slides
    n_pairs, n_slides = len(layout.pairs), len(layout.slides)
    m, S = n_pairs + n_slides, len(ok)
    C = np.zeros((m, n_links + n_slides))  # the unit loads' multiples u = x C, x = (torques,
    C[:n_pairs, :n_links] = A  # slider forces): link couples A^T torques, minus each force
    C[n_pairs:, n_links:] = -np.eye(n_slides)
    CT = np.ascontiguousarray(C.T)
    R = _joined(resp_pairs, resp_normals)  # (m, 2, K, S): per unit of each load
    g0 = _joined(base_pairs, base_normals)  # (m, 2, S)
    coef = np.concatenate([mu_r, mu_s])[:, None]
    sgn = np.ascontiguousarray(np.concatenate([sgn_pair, sgn_slide], axis=1).T)  # (m, S)
    visc = np.ascontiguousarray(np.concatenate([visc_pair, visc_slide], axis=1).T)
    tol = scene.solver.tol
    x = np.zeros((m, S))
    work = np.flatnonzero(ok)  # the steps the working arrays hold (failed steps never)
    Rw, gw, sw, vw = (a if len(work) == S else a[..., work] for a in (R, g0, sgn, visc))
    sw = coef * sw  # the magnitudes' factors: mu r (mu) times the regularised sign
    # the first round from x = 0, where G = g0 (no unit case contributes)
    xw = _magnitude(gw.copy()) * sw + vw
    for _ in range(scene.solver.max_iter):  # each later round tests convergence
        if not len(work):
            break
        u = CT @ xw  # (K, n): the unit cases' multiples
        G = np.einsum("cdks,ks->cds", Rw, u)  # their sum in one pass over the responses
        G += gw
        new = _magnitude(G)
        new *= sw
        new += vw
        change = np.abs(np.subtract(new, xw, out=xw), out=xw)  # xw is replaced below
        with np.errstate(invalid="ignore"):
            done = (change.max(axis=0, initial=0.0)
                    <= tol * np.abs(new).max(axis=0, initial=0.0))
        xw = new
        if done.any():  # converged steps leave the working arrays
            x[:, work[done]] = xw[:, done]
            live = ~done
            work, Rw, gw, sw, vw, xw = (work[live], Rw[..., live], gw[..., live],
                                        sw[:, live], vw[:, live], xw[:, live])
    x[:, work] = xw  # not converged: the last round's values (the caller's status says so)
    converged = ok.copy()
    converged[work] = False
    torque, force = x[:n_pairs].T, x[n_pairs:].T
    return torque, force, torque @ A, converged


def _magnitude(G):
    """(m, n) the length of each force ``G`` (m, 2, n), x then y: ``sqrt(x^2 + y^2)``, in
    ``G``'s own memory (overwritten)."""
    np.square(G, out=G)
    out = G[:, 0]
    out += G[:, 1]
    return np.sqrt(out, out=out)


def _joined(a, b):
    """``a`` and ``b`` one after the other along the first axis (no copy where one is empty)."""
    return a if not len(b) else b if not len(a) else np.concatenate([a, b])


def _column(x):
    """A per-step (S,) scale as (S, 1) to divide (S, n) arrays; a float as it is."""
    return np.asarray(x)[:, None] if np.ndim(x) else x


def applied_of(ctx, layout: Layout, couples, slide_force, Xz) -> Applied:
    """The pins' and sliders' friction as loads: ``couples`` (S, n_links of layout.links),
    ``slide_force`` (S, n_slides) signed (opposing the relative rate)."""
    points, link_couples = ctx.zeros_points(), ctx.zeros_links()
    for k, li in enumerate(layout.links):
        link_couples[:, li] += couples[:, k]
    for c, (_, _, p, d, _) in enumerate(layout.slides):
        f = -slide_force[:, c, None] * guide_direction(ctx, layout, p, d, Xz)
        points[:, p] += f
        if d >= 0:
            points[:, d] -= f
    return Applied(points, link_couples)


def variables(ctx, layout: Layout, seal_signed, s_dot, rates: Rates, torque, force):
    """``friction_force`` (S, n_entries) magnitudes and ``friction_power`` (S, n_entries)."""
    scene, units = ctx.model.scene, ctx.units
    n = len(scene.friction)
    magnitude, power = np.zeros((ctx.n_steps, n)), np.zeros((ctx.n_steps, n))
    for c, (e, j) in enumerate(layout.seals):
        magnitude[:, e] += np.abs(seal_signed[:, c])
        power[:, e] -= seal_signed[:, c] * s_dot[:, j]
    for c, (e, *_) in enumerate(layout.pairs):
        magnitude[:, e] += np.abs(torque[:, c])
        power[:, e] -= torque[:, c] * rates.pairs[:, c]
    for c, (e, *_) in enumerate(layout.slides):
        magnitude[:, e] += np.abs(force[:, c])
        power[:, e] -= force[:, c] * rates.slides[:, c]
    F, L, T = units["force"], units["length"], units["time"]
    common = common_unit(friction_units(scene, units))
    return ({"friction_force": (("step", "friction"), magnitude, common),
             "friction_power": (("step", "friction"), power, f"{F}*{L}/{T}")},
            {"friction": [fr.name for fr in scene.friction]})
