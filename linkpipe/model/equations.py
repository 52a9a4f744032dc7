"""The constraint equations of the natural-coordinate model: the one place each is written.

Unknowns are the x, y of every moving point. The rows, in this order (each a length with an
O(1) gradient, so tolerances scale with the mechanism's size):

1. ``dist``   one per link: ``(|b - a|^2 - L^2) / (2 L)``
2. ``local``  two per further point p of a link: ``p - a - (u d + v d_perp) / L``, d = b - a
3. ``sfix``   one per fixed-guide slider: ``n . (p - c)``, n the guide's unit normal
4. ``smov``   one per moving-guide slider: ``cross(e - d, p - d) / L_de``
5. ``driver`` one per driver: angle ``cross(u(s), b - a)``; coordinate ``p[axis] - s``;
   distance ``(|b - a|^2 - s^2) / (2 L)`` (L: the driver's largest length, a fixed scale, so the
   row's gradient is affine in the coordinates); relative angle
   ``cross(R(s) (d - c), b - a) / L`` (L: the start length of d - c)

Every function here is written once, with + - * / only, on coordinates that may be Python
floats (one step of the sequential continuation), 1-D arrays over steps (the vectorised
paths) or strided views of stacked ``(S, n_points, 2)`` arrays (``Model.phi``): the layouts
evaluate the same expression in the same order, so they agree to the last bit, which
``tests/test_kernels.py`` checks for every shipped scene. Points are read through an accessor
``xy(p) -> (x, y)`` (a fixed point may give floats in any layout), driver trigonometry comes
in as ``cos_s``, ``sin_s`` sequences indexed by driver (the caller computes them once).

Functions yield row values (or Jacobian terms) in row order; callers assemble them.
"""
from __future__ import annotations

from dataclasses import dataclass


#: driver kinds in :class:`Rows` (``drivers[j][0]``)
COORDINATE, ANGLE, DISTANCE, RELATIVE = 0, 1, 2, 3
#: the kind names of :class:`linkpipe.scene.Driver` (a relative angle is an "angle" with
#: ``relative_to``)
KIND_OF = {"coordinate": COORDINATE, "angle": ANGLE, "distance": DISTANCE}


@dataclass(frozen=True)
class Rows:
    """The row families of one model as plain Python numbers (point indices and lengths).

    ``dist``: (a, b, L); ``local``: (a, b, p, u, v, L); ``sfix``: (p, cx, cy, nx, ny);
    ``smov``: (p, d, e, L); ``drivers``: (kind, a, b, axis, c, d, L) (-1 / 0.0 where unused):
    ``kind`` one of :data:`COORDINATE`, :data:`ANGLE`, :data:`DISTANCE`, :data:`RELATIVE`.
    """

    dist: tuple
    local: tuple
    sfix: tuple
    smov: tuple
    drivers: tuple

    @property
    def n_constraints(self) -> int:
        return len(self.dist) + 2 * len(self.local) + len(self.sfix) + len(self.smov)

    @property
    def n_rows(self) -> int:
        return self.n_constraints + len(self.drivers)

    FAMILIES = ("dist", "local", "sfix", "smov", "drivers")

    def arrays(self) -> list:
        """Every number given per row (a study's variants on one (variant, step) row axis:
        1-D arrays over the rows), in row-family order; [] for a model's own rows."""
        return [x for family in self.FAMILIES for row in getattr(self, family) for x in row
                if hasattr(x, "shape")]

    def take(self, rows) -> "Rows":
        """These rows' constants at ``rows`` (an index or slice of the row axis): each number
        given per row indexed, plain numbers as they are (the model's own rows: itself)."""
        if not self.arrays():
            return self
        return Rows(**{family: tuple(tuple(x[rows] if hasattr(x, "shape") else x for x in row)
                                     for row in getattr(self, family))
                       for family in self.FAMILIES})


def phi_rows(rows: Rows, xy, s, cos_s, sin_s):
    """Yield Φ's rows in order: the residual of every constraint and driver."""
    for a, b, L in rows.dist:
        ax, ay = xy(a)
        bx, by = xy(b)
        dx, dy = bx - ax, by - ay
        yield (dx * dx + dy * dy - L * L) / (2 * L)
    for a, b, p, u, v, L in rows.local:
        ax, ay = xy(a)
        bx, by = xy(b)
        px, py = xy(p)
        dx, dy = bx - ax, by - ay
        yield px - ax - (u * dx - v * dy) / L
        yield py - ay - (u * dy + v * dx) / L
    for p, cx, cy, nx, ny in rows.sfix:
        px, py = xy(p)
        yield (px - cx) * nx + (py - cy) * ny
    for p, d, e, L in rows.smov:
        px, py = xy(p)
        dx, dy = xy(d)
        ex, ey = xy(e)
        yield ((ex - dx) * (py - dy) - (ey - dy) * (px - dx)) / L
    for j, (kind, a, b, axis, c, d, L) in enumerate(rows.drivers):
        ax, ay = xy(a)
        if kind == ANGLE:
            bx, by = xy(b)
            yield cos_s[j] * (by - ay) - sin_s[j] * (bx - ax)
        elif kind == COORDINATE:
            yield (ax, ay)[axis] - s[j]
        elif kind == DISTANCE:
            bx, by = xy(b)
            dx, dy = bx - ax, by - ay
            yield (dx * dx + dy * dy - s[j] * s[j]) / (2 * L)
        else:
            bx, by = xy(b)
            cx, cy = xy(c)
            ex, ey = xy(d)
            rx, ry, dx, dy = ex - cx, ey - cy, bx - ax, by - ay
            yield (cos_s[j] * (rx * dy - ry * dx) - sin_s[j] * (rx * dx + ry * dy)) / L


def jacobian_terms(rows: Rows, xy, cos_s, sin_s):
    """Yield Φq's non-zero terms ``(row, point, dphi/dx, dphi/dy)`` (a point may recur in a
    row: add the terms)."""
    r = 0
    for a, b, L in rows.dist:
        ax, ay = xy(a)
        bx, by = xy(b)
        gx, gy = (bx - ax) / L, (by - ay) / L
        yield r, b, gx, gy
        yield r, a, -gx, -gy
        r += 1
    for a, b, p, u, v, L in rows.local:
        m00, m01 = u / L, -v / L  # (u I + v R90) / L, row by row
        m10, m11 = v / L, u / L
        yield r, p, 1.0, 0.0
        yield r, a, -1.0 + m00, m01
        yield r, b, -m00, -m01
        yield r + 1, p, 0.0, 1.0
        yield r + 1, a, m10, -1.0 + m11
        yield r + 1, b, -m10, -m11
        r += 2
    for p, cx, cy, nx, ny in rows.sfix:
        yield r, p, nx, ny
        r += 1
    for p, d, e, L in rows.smov:
        px, py = xy(p)
        dx, dy = xy(d)
        ex, ey = xy(e)
        dex, dey = (py - dy) / L, -(px - dx) / L  # d cross / d e
        dfx, dfy = -(ey - dy) / L, (ex - dx) / L  # d cross / d p
        yield r, e, dex, dey
        yield r, p, dfx, dfy
        yield r, d, -dex - dfx, -dey - dfy
        r += 1
    for j, driver in enumerate(rows.drivers):
        yield from driver_jacobian_terms(driver, r + j, xy, cos_s[j], sin_s[j])


def driver_jacobian_terms(driver, r: int, xy, c, sn):
    """Yield the Jacobian terms ``(row, point, dphi/dx, dphi/dy)`` of one driver's row ``r``
    (``c``, ``sn``: cos and sin of its value; unused for lengths). A relative angle's terms come
    in two groups, the driven vector's points (b, a) then the reference's (d, c)."""
    kind, a, b, axis, pc, pd, L = driver
    if kind == ANGLE:
        yield r, b, -sn, c
        yield r, a, sn, -c
    elif kind == COORDINATE:
        yield r, a, (1.0, 0.0)[axis], (0.0, 1.0)[axis]
    elif kind == DISTANCE:
        ax, ay = xy(a)
        bx, by = xy(b)
        gx, gy = (bx - ax) / L, (by - ay) / L
        yield r, b, gx, gy
        yield r, a, -gx, -gy
    else:
        for point, gx, gy in relative_gradient(driver, xy, c, sn):
            yield r, point, gx, gy


def relative_gradient(driver, xy, c, sn):
    """Yield a relative angle row's gradient ``(point, dphi/dx, dphi/dy)`` at b, a (the driven
    vector's head and tail) then d, c (the reference's): the first two are the motor's couple
    on the driven body, the last two its reaction on the reference body."""
    _, a, b, _, pc, pd, L = driver
    ax, ay = xy(a)
    bx, by = xy(b)
    cx, cy = xy(pc)
    ex, ey = xy(pd)
    rx, ry, dx, dy = ex - cx, ey - cy, bx - ax, by - ay
    gdx, gdy = (-c * ry - sn * rx) / L, (c * rx - sn * ry) / L  # d phi / d(b - a)
    grx, gry = (c * dy - sn * dx) / L, (-c * dx - sn * dy) / L  # d phi / d(d - c)
    yield b, gdx, gdy
    yield a, -gdx, -gdy
    yield pd, grx, gry
    yield pc, -grx, -gry


def phi_s_rows(rows: Rows, xy, s, cos_s, sin_s):
    """Yield dΦ_driver/ds, one per driver (each driver row depends on its own value only)."""
    for j, (kind, a, b, axis, pc, pd, L) in enumerate(rows.drivers):
        if kind == ANGLE:
            ax, ay = xy(a)
            bx, by = xy(b)
            yield -(cos_s[j] * (bx - ax) + sin_s[j] * (by - ay))
        elif kind == COORDINATE:
            yield -1.0
        elif kind == DISTANCE:
            yield -s[j] / L
        else:
            ax, ay = xy(a)
            bx, by = xy(b)
            cx, cy = xy(pc)
            ex, ey = xy(pd)
            rx, ry, dx, dy = ex - cx, ey - cy, bx - ax, by - ay
            yield -(sin_s[j] * (rx * dy - ry * dx) + cos_s[j] * (rx * dx + ry * dy)) / L


def gamma_rows(rows: Rows, xy, vxy, s, s_dot, s_ddot, cos_s, sin_s):
    """Yield γ's rows in order (Φq q̈ = γ), with point velocities read through ``vxy``."""
    for a, b, L in rows.dist:
        avx, avy = vxy(a)
        bvx, bvy = vxy(b)
        dvx, dvy = bvx - avx, bvy - avy
        yield -(dvx * dvx + dvy * dvy) / L
    for _ in range(2 * len(rows.local) + len(rows.sfix)):
        yield 0.0  # linear in the coordinates: no velocity terms
    for p, d, e, L in rows.smov:
        pvx, pvy = vxy(p)
        dvx, dvy = vxy(d)
        evx, evy = vxy(e)
        yield -2.0 * ((evx - dvx) * (pvy - dvy) - (evy - dvy) * (pvx - dvx)) / L
    for j, driver in enumerate(rows.drivers):
        kind, a, b = driver[:3]
        if kind == COORDINATE:
            yield s_ddot[j]
            continue
        if kind == DISTANCE:
            avx, avy = vxy(a)
            bvx, bvy = vxy(b)
            dvx, dvy = bvx - avx, bvy - avy
            yield -(dvx * dvx + dvy * dvy - s_dot[j] * s_dot[j] - s[j] * s_ddot[j]) / driver[6]
            continue
        if kind == RELATIVE:
            yield _relative_gamma(driver, xy, vxy, s_dot[j], s_ddot[j], cos_s[j], sin_s[j])
            continue
        c, sn, w, al = cos_s[j], sin_s[j], s_dot[j], s_ddot[j]
        ax, ay = xy(a)
        bx, by = xy(b)
        avx, avy = vxy(a)
        bvx, bvy = vxy(b)
        dx, dy, ddx, ddy = bx - ax, by - ay, bvx - avx, bvy - avy
        yield al * (c * dx + sn * dy) + w * w * (c * dy - sn * dx) + 2 * w * (c * ddx + sn * ddy)


def _relative_gamma(driver, xy, vxy, w, al, c, sn):
    """γ of a relative angle row ``(c X - sn Y) / L`` with X = cross(r, d), Y = r . d (r = d - c
    of the reference, d = b - a of the driven vector): minus every term of its second time
    derivative that does not hold an acceleration."""
    _, a, b, _, pc, pd, L = driver
    ax, ay = xy(a)
    bx, by = xy(b)
    cx, cy = xy(pc)
    ex, ey = xy(pd)
    avx, avy = vxy(a)
    bvx, bvy = vxy(b)
    cvx, cvy = vxy(pc)
    evx, evy = vxy(pd)
    rx, ry, dx, dy = ex - cx, ey - cy, bx - ax, by - ay
    rvx, rvy, dvx, dvy = evx - cvx, evy - cvy, bvx - avx, bvy - avy
    X, Y = rx * dy - ry * dx, rx * dx + ry * dy
    Xd = (rvx * dy - rvy * dx) + (rx * dvy - ry * dvx)
    Yd = (rvx * dx + rvy * dy) + (rx * dvx + ry * dvy)
    cross_v, dot_v = rvx * dvy - rvy * dvx, rvx * dvx + rvy * dvy
    rest = (2 * (c * cross_v - sn * dot_v) - 2 * w * (sn * Xd + c * Yd) - al * (sn * X + c * Y)
            - w * w * (c * X - sn * Y))
    return -rest / L


def alignment_rows(rows: Rows, xy, cos_s, sin_s):
    """Yield ``(j, value)`` for every angle driver j: the driven vector's component along the
    direction its value asks for (positive on the true root; the row's other root, the
    direction turned half a turn, gives a negative value)."""
    for j, (kind, a, b, _, pc, pd, L) in enumerate(rows.drivers):
        if kind == ANGLE or kind == RELATIVE:
            ax, ay = xy(a)
            bx, by = xy(b)
            dx, dy = bx - ax, by - ay
            if kind == ANGLE:
                yield j, dx * cos_s[j] + dy * sin_s[j]
                continue
            cx, cy = xy(pc)
            ex, ey = xy(pd)
            rx, ry = ex - cx, ey - cy
            yield j, cos_s[j] * (rx * dx + ry * dy) + sin_s[j] * (rx * dy - ry * dx)


def _number(x):
    """A length of a row: a plain float, or 1-D values over variants or rows, kept an array."""
    return float(x) if getattr(x, "ndim", 0) == 0 else x


def rows_of(dist_a, dist_b, dist_len, loc_a, loc_b, loc_p, loc_u, loc_v, loc_len, sfix_p, sfix_c,
            sfix_n, smov_p, smov_d, smov_e, smov_len, drv_kind, drv_a, drv_b, drv_axis, drv_c,
            drv_d, drv_len, **_) -> Rows:
    """Return the :class:`Rows` of a model's index arrays (plain ints and floats; a length or
    local coordinate given as values over variants, ``loc_u[k]`` an array, stays an array)."""
    return Rows(
        dist=tuple((int(a), int(b), _number(L)) for a, b, L in zip(dist_a, dist_b, dist_len)),
        local=tuple((int(a), int(b), int(p), _number(u), _number(v), _number(L)) for a, b, p, u, v, L
                    in zip(loc_a, loc_b, loc_p, loc_u, loc_v, loc_len)),
        sfix=tuple((int(p), _number(c[0]), _number(c[1]), _number(n[0]), _number(n[1]))
                   for p, c, n in zip(sfix_p, sfix_c, sfix_n)),
        smov=tuple((int(p), int(d), int(e), _number(L))
                   for p, d, e, L in zip(smov_p, smov_d, smov_e, smov_len)),
        drivers=tuple((int(k), int(a), int(b), int(x), int(c), int(d), _number(L)) for k, a, b, x, c, d, L
                      in zip(drv_kind, drv_a, drv_b, drv_axis, drv_c, drv_d, drv_len)))
