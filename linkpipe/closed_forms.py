"""Closed-form kinematics of the textbook mechanisms, independent of linkpipe's solver.

Four-bar: Norton, Design of Machinery, eqs. 4.10 (position), 6.18 (velocity), 7.12
(acceleration), with ground O2 at the origin and O4 at (d, 0). Slider-crank with offset e:
x_B = a cos(t) + sqrt(b^2 - (a sin(t) - e)^2), differentiated by hand. Cylinder-driven rocker
(a body pinned at O, a linear actuator of length s from a fixed pin C to its pin P): the law of
cosines s^2 = rp^2 + rc^2 - 2 rp rc cos(beta), differentiated by hand.
All functions take arrays of crank angles (rad) and return arrays, step axis first.

:func:`detect` recognises these mechanisms in a scene *structurally* (links, fixed pivots,
sliders, the driver), whatever the point names, pivot positions, ground orientation or
assembly branch; :func:`evaluate` then gives every point's position, velocity and
acceleration in the scene's frame (further points of a link from their local coordinates).
The accuracy ladder (:mod:`linkpipe.accuracy`) uses them as its exact reference.
numpy only; no linkpipe solver code is used here.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["fourbar", "slider_crank", "cylinder_rocker", "ClosedForm", "detect", "evaluate"]


def _nan_quietly(fn):
    """Run ``fn`` with numpy's invalid/divide warnings off: out of range or at a singular
    configuration the formulas give NaN (or inf) on purpose, step by step."""
    import functools

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with np.errstate(invalid="ignore", divide="ignore"):
            return fn(*args, **kwargs)

    return wrapper


@_nan_quietly
def fourbar(a, b, c, d, theta2, omega2, alpha2, branch=+1, coupler_uv=(0.0, 0.0)):
    """Return dict of A, B, P positions/velocities/accelerations (S, 2) and theta3/theta4/omegas."""
    t2 = np.asarray(theta2, float)
    A = np.stack([a * np.cos(t2), a * np.sin(t2)], -1)
    O4 = np.array([d, 0.0])
    # B: intersection of circle(A, b) and circle(O4, c); branch +1 = left of A->O4
    v = O4 - A
    dist = np.linalg.norm(v, axis=-1)
    along = (b**2 - c**2 + dist**2) / (2 * dist)
    h = np.sqrt(b**2 - along**2)  # out of the assembly range: NaN
    e = v / dist[:, None]
    ep = np.stack([-e[:, 1], e[:, 0]], -1)
    B = A + along[:, None] * e + branch * h[:, None] * ep
    t3 = np.arctan2(B[:, 1] - A[:, 1], B[:, 0] - A[:, 0])
    t4 = np.arctan2(B[:, 1] - O4[1], B[:, 0] - O4[0])
    w2 = np.asarray(omega2, float)  # a constant rate, or one per step (S,)
    al2 = np.asarray(alpha2, float)
    w3 = a * w2 / b * np.sin(t4 - t2) / np.sin(t3 - t4)
    w4 = a * w2 / c * np.sin(t2 - t3) / np.sin(t4 - t3)
    # acceleration (Norton 7.12 with R4 from O4 to B)
    Aa = c * np.sin(t4); Bb = b * np.sin(t3)
    Cc = a * al2 * np.sin(t2) + a * w2**2 * np.cos(t2) + b * w3**2 * np.cos(t3) - c * w4**2 * np.cos(t4)
    Dd = c * np.cos(t4); Ee = b * np.cos(t3)
    Ff = a * al2 * np.cos(t2) - a * w2**2 * np.sin(t2) - b * w3**2 * np.sin(t3) + c * w4**2 * np.sin(t4)
    al3 = (Cc * Dd - Aa * Ff) / (Aa * Ee - Bb * Dd)
    al4 = (Cc * Ee - Bb * Ff) / (Aa * Ee - Bb * Dd)

    def perp(x):
        return np.stack([-x[:, 1], x[:, 0]], -1)

    e2 = np.stack([np.cos(t2), np.sin(t2)], -1)
    e3 = np.stack([np.cos(t3), np.sin(t3)], -1)
    e4 = np.stack([np.cos(t4), np.sin(t4)], -1)
    w2c, al2c = w2[..., None], al2[..., None]  # against (S, 2) vectors
    VA = a * w2c * perp(e2)
    AA = a * al2c * perp(e2) - a * w2c**2 * e2
    VB = c * w4[:, None] * perp(e4)
    AB = c * al4[:, None] * perp(e4) - c * (w4**2)[:, None] * e4
    u, vv = coupler_uv
    r = u * e3 + vv * perp(e3)
    P = A + r
    VP = VA + w3[:, None] * perp(r)
    AP = AA + al3[:, None] * perp(r) - (w3**2)[:, None] * r
    return dict(A=A, B=B, P=P, VA=VA, VB=VB, VP=VP, AA=AA, AB=AB, AP=AP,
                theta3=t3, theta4=t4, omega3=w3, omega4=w4, alpha3=al3, alpha4=al4)


@_nan_quietly
def slider_crank(a, b, e, theta, omega, alpha, branch=+1):
    """Return A, B positions, velocities, accelerations (S, 2) of an offset slider-crank.

    The guide is the line y = e; ``branch`` +1 puts the slider B ahead of A along +x, -1 behind.
    """
    t = np.asarray(theta, float)
    s, c = np.sin(t), np.cos(t)
    h = a * s - e
    r = np.sqrt(b**2 - h**2)  # out of the assembly range: NaN
    x = a * c + branch * r
    hd = a * c * omega
    hdd = -a * s * omega**2 + a * c * alpha
    xd = -a * s * omega - branch * h * hd / r
    xdd = (-a * c * omega**2 - a * s * alpha
           + branch * (-(hd**2 + h * hdd) / r - h**2 * hd**2 / r**3))
    z = np.zeros_like(t)
    A = np.stack([a * c, a * s], -1)
    VA = np.stack([-a * s * omega, a * c * omega], -1)
    AA = np.stack([-a * c * omega**2 - a * s * alpha, -a * s * omega**2 + a * c * alpha], -1)
    B = np.stack([x, z + e], -1)
    VB = np.stack([xd, z], -1)
    AB = np.stack([xdd, z], -1)
    return dict(A=A, B=B, VA=VA, VB=VB, AA=AA, AB=AB)


@_nan_quietly
def cylinder_rocker(rp, rc, s, s_dot, s_ddot, branch=+1):
    """Return the angle (from O->C to O->P, signed by ``branch``), its rate and its acceleration
    (S,) of a body pinned at O whose pin P (rp from O) is pushed by a cylinder of length s from
    the fixed pin C (rc from O); out of reach: NaN."""
    s = np.asarray(s, float)
    k = 1.0 / (rp * rc)
    cos_b = (rp * rp + rc * rc - s * s) * (0.5 * k)
    sin_b = np.sqrt(1.0 - cos_b * cos_b)
    beta = np.arccos(cos_b)
    d1 = s * k / sin_b  # d beta / ds
    d2 = k / sin_b - s * s * k * k * cos_b / sin_b ** 3  # d2 beta / ds2
    return branch * beta, branch * d1 * s_dot, branch * (d2 * s_dot * s_dot + d1 * s_ddot)


# ------------------------------------------------------------------ scenes with a closed form
@dataclass(frozen=True)
class ClosedForm:
    """A scene recognised as a textbook mechanism, in the canonical frame of the formulas.

    ``kind`` "fourbar", "slider_crank" or "cylinder_rocker". ``joints`` maps the formula's
    roles to point indices (fourbar: O2, A, B, O4; slider_crank: O, A, B; cylinder_rocker: O,
    C, P and ``body``, every point of the rocker; its ``angle`` is that of O->C, ``flip`` the
    drawn angle of O->P, ``lengths`` (rp, rc)). ``origin`` and ``angle`` place the canonical
    frame (crank pivot at the origin, x axis towards O4 / along the guide) in the scene.
    ``lengths``: a, b, c, d (fourbar) or a, b, e (slider-crank). ``flip``: pi when the driver's
    vector points from the crank's joint to its pivot. ``branch``: the assembly of the start
    configuration. ``further``: (point, frame a, frame b, u, v) of every other moving point.
    """

    kind: str
    joints: dict
    origin: np.ndarray
    angle: float
    lengths: tuple
    flip: float
    branch: int
    further: tuple

    @property
    def description(self) -> str:
        if self.kind == "fourbar":
            return "closed form (four-bar, Norton 4.10/6.18/7.12)"
        if self.kind == "cylinder_rocker":
            return "closed form (cylinder-driven rocker, law of cosines)"
        return "closed form (offset slider-crank)"


def _frames(scene):
    """Return (index, X0, fixed, link frames (a, b, L), further points) of a scene."""
    names = scene.point_names
    index = {n: i for i, n in enumerate(names)}
    X0 = np.array([[p.x, p.y] for p in scene.points], dtype=float)
    fixed = np.array([p.fixed for p in scene.points], dtype=bool)
    frames, further = [], []
    for link in scene.links:
        ia, ib = index[link.points[0]], index[link.points[1]]
        d0 = X0[ib] - X0[ia]
        L0 = float(np.hypot(*d0))
        L = float(link.length) if link.length is not None else L0
        frames.append((ia, ib, L))
        e = d0 / L0
        ep = np.array([-e[1], e[0]])
        for pname in link.points[2:]:
            ip = index[pname]
            if pname in link.local:
                u, v = link.local[pname]
            else:
                r = X0[ip] - X0[ia]
                u, v = float(r @ e), float(r @ ep)
            further.append((ip, ia, ib, float(u), float(v)))
    return index, X0, fixed, frames, tuple(further)


def _cross(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def detect(scene, start: np.ndarray | None = None) -> ClosedForm | None:
    """Return the closed form of ``scene`` when it is a four-bar or slider-crank, else None.

    Four-bar: 3 links, no sliders, 2 fixed pivots (one on each of two links), the coupler joining
    the two other joints, one angle driver on the crank's pivot and joint. Slider-crank: 2 links,
    1 fixed-guide slider on the rod's free end, 1 fixed pivot on the crank, one angle driver on
    the crank. Every link's first two points must be its joints (further points are placed by
    their local coordinates). ``start`` (n_points, 2): an assembled configuration that picks the
    branch (default: the scene's start as written).
    """
    if len(scene.drivers) == 1 and scene.drivers[0].kind == "distance":
        return _detect_cylinder_rocker(scene, start)
    if len(scene.drivers) != 1 or scene.drivers[0].kind != "angle":
        return None
    if scene.drivers[0].relative_to is not None:
        return None
    index, X0, fixed, frames, further = _frames(scene)
    X = X0 if start is None else np.asarray(start, dtype=float)
    drv = scene.drivers[0]
    da, db = index[drv.points[0]], index[drv.points[1]]
    links = [tuple(index[p] for p in l.points) for l in scene.links]
    pivots = [[i for i in pts if fixed[i]] for pts in links]
    if any(len(p) > 1 for p in pivots):
        return None
    grounded = [k for k, p in enumerate(pivots) if p]
    joints = [set(frames[k][:2]) for k in range(len(links))]

    def shared(k1, k2):
        common = set(links[k1]) & set(links[k2])
        return common.pop() if len(common) == 1 else None

    if len(links) == 3 and not scene.sliders and len(grounded) == 2:
        (coupler,) = [k for k in range(3) if k not in grounded]
        crank = next((k for k in grounded if {da, db} == joints[k]), None)
        if crank is None:
            return None
        rocker = grounded[0] if grounded[1] == crank else grounded[1]
        O2, O4 = pivots[crank][0], pivots[rocker][0]
        A, B = shared(crank, coupler), shared(rocker, coupler)
        if (A is None or B is None or A == B or joints[crank] != {O2, A}
                or joints[rocker] != {O4, B} or joints[coupler] != {A, B}
                or shared(crank, rocker) is not None):
            return None
        g = X0[O4] - X0[O2]
        angle = float(np.arctan2(g[1], g[0]))
        branch = 1 if _cross(X[O4] - X[A], X[B] - X[A]) > 0 else -1
        lengths = (frames[crank][2], frames[coupler][2], frames[rocker][2], float(np.hypot(*g)))
        return ClosedForm("fourbar", dict(O2=O2, A=A, B=B, O4=O4), X0[O2].copy(), angle, lengths,
                          0.0 if da == O2 else np.pi, branch, further)

    if len(links) == 2 and len(scene.sliders) == 1 and len(grounded) == 1:
        sl = scene.sliders[0]
        if sl.moving:
            return None
        crank = grounded[0]
        rod = 1 - crank
        O = pivots[crank][0]
        A = shared(crank, rod)
        B = index[sl.point]
        if (A is None or fixed[B] or B not in joints[rod] or joints[crank] != {O, A}
                or joints[rod] != {A, B} or {da, db} != {O, A}):
            return None
        u = np.asarray(sl.direction, dtype=float)
        u = u / np.hypot(*u)
        angle = float(np.arctan2(u[1], u[0]))
        n = np.array([-u[1], u[0]])
        e = float((np.asarray(sl.through, dtype=float) - X0[O]) @ n)
        branch = 1 if (X[B] - X[A]) @ u > 0 else -1
        return ClosedForm("slider_crank", dict(O=O, A=A, B=B), X0[O].copy(), angle,
                          (frames[crank][2], frames[rod][2], e), 0.0 if da == O else np.pi,
                          branch, further)
    return None


def _detect_cylinder_rocker(scene, start) -> ClosedForm | None:
    """One link pinned at one fixed point O, every moving point on it, no sliders, one distance
    driver from a fixed pin C to a point P of the link."""
    index, X0, fixed, frames, further = _frames(scene)
    X = X0 if start is None else np.asarray(start, dtype=float)
    moving_links = [l for l in scene.links if not all(fixed[index[p]] for p in l.points)]
    if len(moving_links) != 1 or scene.sliders:
        return None
    body = [index[p] for p in moving_links[0].points]
    pivots = [i for i in body if fixed[i]]
    a, b = (index[p] for p in scene.drivers[0].points)
    C, P = (a, b) if fixed[a] else (b, a)
    if (len(pivots) != 1 or not fixed[C] or fixed[P] or P not in body
            or any(not fixed[i] and i not in body for i in range(len(X0)))):
        return None
    O = pivots[0]
    branch = 1 if _cross(X[C] - X[O], X[P] - X[O]) > 0 else -1
    rp, rc = float(np.hypot(*(X0[P] - X0[O]))), float(np.hypot(*(X0[C] - X0[O])))
    angle = float(np.arctan2(*(X0[C] - X0[O])[::-1]))
    drawn_p = float(np.arctan2(*(X0[P] - X0[O])[::-1]))
    return ClosedForm("cylinder_rocker", dict(O=O, C=C, P=P, body=tuple(body)), X0[O].copy(),
                      angle, (rp, rc), drawn_p, branch, ())


def _evaluate_cylinder_rocker(form: ClosedForm, X0, s, w, al):
    """Every point of the rocker turned rigidly about O from its drawing (S, P, 2) x 3."""
    rp, rc = form.lengths
    beta, beta_d, beta_dd = cylinder_rocker(rp, rc, s, w, al, form.branch)
    turn = form.angle + beta - form.flip  # the body's rotation from the drawing
    S = len(s)
    X = np.broadcast_to(X0, (S,) + X0.shape).copy()
    V, A = np.zeros_like(X), np.zeros_like(X)
    c, sn = np.cos(turn), np.sin(turn)
    for i in form.joints["body"]:
        if i == form.joints["O"]:
            continue
        r0 = X0[i] - form.origin
        rx, ry = c * r0[0] - sn * r0[1], sn * r0[0] + c * r0[1]
        X[:, i] = form.origin + np.stack([rx, ry], -1)
        V[:, i] = np.stack([-beta_d * ry, beta_d * rx], -1)
        A[:, i] = np.stack([-beta_dd * ry - beta_d ** 2 * rx, beta_dd * rx - beta_d ** 2 * ry], -1)
    return X, V, A


def evaluate(form: ClosedForm, scene, s, s_dot, s_ddot):
    """Return positions, velocities, accelerations (S, n_points, 2) of every point.

    ``s``, ``s_dot``, ``s_ddot`` (S,) or (S, 1): the driver's angle (rad, direction of its vector
    from +x), rate and acceleration at each step (a time-driven sweep's vary; a scalar or a
    single value is taken for every step). Steps outside the assembly range are NaN.
    """
    s = np.asarray(s, dtype=float).reshape(-1)
    w, al = (np.broadcast_to(np.asarray(x, dtype=float).reshape(-1) if np.size(x) else 0.0,
                             s.shape).copy() for x in (s_dot, s_ddot))
    X0 = np.array([[p.x, p.y] for p in scene.points], dtype=float)
    if form.kind == "cylinder_rocker":
        return _evaluate_cylinder_rocker(form, X0, s, w, al)
    S = len(s)
    theta = s + form.flip - form.angle  # crank angle in the canonical frame
    if form.kind == "fourbar":
        a, b, c, d = form.lengths
        cf = fourbar(a, b, c, d, theta, w, al, branch=form.branch)
        roles = dict(A="A", B="B")
        canon_fixed = dict(O2=np.zeros(2), O4=np.array([d, 0.0]))
    else:
        a, b, e = form.lengths
        cf = slider_crank(a, b, e, theta, w, al, branch=form.branch)
        roles = dict(A="A", B="B")
        canon_fixed = dict(O=np.zeros(2))
    c, sn = np.cos(form.angle), np.sin(form.angle)
    R = np.array([[c, -sn], [sn, c]])
    X = np.broadcast_to(X0, (S,) + X0.shape).copy()
    V = np.zeros_like(X)
    A = np.zeros_like(X)
    known = {form.joints[k] for k in canon_fixed}
    for role, key in roles.items():
        i = form.joints[role]
        X[:, i] = form.origin + cf[key] @ R.T
        V[:, i] = cf["V" + key] @ R.T
        A[:, i] = cf["A" + key] @ R.T
        known.add(i)
    known |= {i for i, p in enumerate(scene.points) if p.fixed}
    pending = list(form.further)
    while pending:  # further points, possibly framed by other further points' links
        rest = []
        for ip, ia, ib, u, v in pending:
            if ip in known:
                continue
            if ia not in known or ib not in known:
                rest.append((ip, ia, ib, u, v))
                continue
            L = np.hypot(*(X[:, ib] - X[:, ia]).T)[:, None]  # the link's (constant) length
            for arr in (X, V, A):  # p = a + (u d + v d_perp) / L is linear in a and b
                dd = arr[:, ib] - arr[:, ia]
                arr[:, ip] = arr[:, ia] + (u * dd + v * np.stack([-dd[:, 1], dd[:, 0]], -1)) / L
            known.add(ip)
        if len(rest) == len(pending):
            raise ValueError("closed form: a point is not placed by the known joints")
        pending = rest
    if len(known) < len(scene.points):
        raise ValueError("closed form: a moving point belongs to no link")
    return X, V, A
