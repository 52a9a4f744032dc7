"""How a scene decomposes into closed-form dyads (the fast path's plan), found once from the
scene's graph: which points each dyad places from which known points, circles and lines."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..model import Model
from ..model import equations as eq
from ..scene.sides import drawn_local


@dataclass
class Body:
    """One link as a rigid body: its point indices and their local coordinates (n, 2), or
    (V, n, 2) for V variants of the model's numbers (:func:`bodies_of` with ``rows``)."""

    name: str
    points: list[int]
    local: np.ndarray


@dataclass
class Line:
    """A line a point lies on: ``fixed`` (o, t), ``moving`` through points d, e, or ``coord``.

    ``coord``: the line ``x = s_j`` (axis 0) or ``y = s_j`` (axis 1) of coordinate driver j.
    """

    kind: str
    o: tuple[float, float] = (0.0, 0.0)
    t: tuple[float, float] = (1.0, 0.0)
    d: int = -1
    e: int = -1
    driver: int = -1
    axis: int = -1


@dataclass
class Dyad:
    """One closed-form step. ``kind`` as in the module docstring; ``targets`` the new points."""

    kind: str
    targets: list[int]
    # angle: pin c, driver j, local vectors w (one per target) in the driver's frame
    c: int = -1
    driver: int = -1
    w: list[tuple[float, float]] = field(default_factory=list)
    # linear: frame points i, j and (alpha, beta) per target: p = xi + alpha d + beta perp(d)
    i: int = -1
    j: int = -1
    ab: list[tuple[float, float]] = field(default_factory=list)
    # circles: centres c1, c2 and radii; circle_line: centre c1, radius r1 and line1;
    # lines: line1, line2. sign: the branch (+1/-1)
    c1: int = -1
    r1: float = 0.0
    c2: int = -1
    r2: float = 0.0
    # a circle whose radius is a distance driver's value (a cylinder): its index, else -1
    r1_driver: int = -1
    r2_driver: int = -1
    line1: Line | None = None
    line2: Line | None = None
    sign: float = 1.0
    ambiguous: bool = False
    # where the constants come from (:func:`chain_at`): linear (body, i, j, by_distance);
    # angle (body, a, b, c) with the targets' local indices in ``local_targets``; circles and
    # circle_line ((body, c, p) or None for a driven radius, one per circle)
    source: tuple = ()
    local_targets: list[int] = field(default_factory=list)

    def take(self, rows) -> "Dyad":
        """The dyad with each constant given per row (arrays) taken at ``rows`` (an index or a
        slice of the row axis); itself where every constant is a plain number."""
        def at(x):
            return x[rows] if isinstance(x, np.ndarray) else x

        if not any(isinstance(x, np.ndarray) for x in
                   (self.r1, self.r2, *(c for pair in self.w + self.ab for c in pair))):
            return self
        return dataclasses.replace(self, r1=at(self.r1), r2=at(self.r2),
                                   w=[(at(x), at(y)) for x, y in self.w],
                                   ab=[(at(x), at(y)) for x, y in self.ab])

    def describe(self, names) -> str:
        tg = ",".join(names[p] for p in self.targets)
        if self.kind == "angle":
            return f"angle({tg} about {names[self.c]}, driver {self.driver})"
        if self.kind == "linear":
            return f"linear({tg} from {names[self.i]},{names[self.j]})"
        r1 = f"r{self.r1:g}" if self.r1_driver < 0 else f"r=driver {self.r1_driver}"
        r2 = f"r{self.r2:g}" if self.r2_driver < 0 else f"r=driver {self.r2_driver}"
        if self.kind == "circles":
            return f"circles({tg}: {names[self.c1]} {r1}, {names[self.c2]} {r2})"
        if self.kind == "circle_line":
            return f"circle_line({tg}: {names[self.c1]} {r1}, {self.line1.kind} line)"
        return f"lines({tg})"


@dataclass
class DyadChain:
    """A scene's dyad decomposition: ``steps`` in order, or ``reason`` why there is none."""

    model: Model
    steps: list[Dyad]
    reason: str = ""

    @property
    def ok(self) -> bool:
        return not self.reason

    def describe(self) -> str:
        if not self.ok:
            return f"does not decompose: {self.reason}"
        return " -> ".join(st.describe(self.model.point_names) for st in self.steps)

    def take(self, rows) -> "DyadChain":
        """The chain with its per-row constants taken at ``rows`` (:meth:`Dyad.take`)."""
        return DyadChain(self.model, [st.take(rows) for st in self.steps], self.reason)


def bodies_of(model: Model, rows=None) -> list[Body]:
    """Return every link as a body with local coordinates (a at 0, b at (L, 0), others (u, v)),
    read off the model's rows; ``rows``: V variants' rows (:func:`linkpipe.model.rows.variant_rows`),
    each body's local coordinates then (V, n, 2)."""
    scene = model.scene
    rows = model.rows if rows is None else rows
    names = model.point_names
    index = {n: i for i, n in enumerate(names)}
    X0 = model.start_position
    length = {int(li): L for (_, _, L), li in zip(rows.dist, model.dist_link)}
    loc = {}
    for (_, _, p, u, v, L), li in zip(rows.local, model.loc_link):
        length.setdefault(int(li), L)
        loc[(int(li), p)] = (u, v)
    out = []
    for li, link in enumerate(scene.links):
        pts = [index[p] for p in link.points]
        ia, ib = pts[0], pts[1]
        L0 = float(np.hypot(*(X0[ib] - X0[ia])))
        L = length.get(li, float(link.length) if link.length is not None else L0)
        local = [(0.0, 0.0), (L, 0.0)]
        for ip in pts[2:]:
            if (li, ip) in loc:
                local.append(loc[(li, ip)])
            else:  # a fixed point of a fixed link: no rows
                local.append(drawn_local(*X0[ia], *X0[ib], *X0[ip]))
        out.append(Body(link.name, pts, _stacked_local(local)))
    return out


def _stacked_local(local: list) -> np.ndarray:
    """Local coordinates [(u, v), ...] of n points -> (n, 2), or (V, n, 2) where some are (V,)."""
    if not any(isinstance(x, np.ndarray) for pair in local for x in pair):
        return np.array(local, dtype=float)
    n_variants = max(len(x) for pair in local for x in pair if isinstance(x, np.ndarray))
    return np.stack([np.stack([np.broadcast_to(np.asarray(x, dtype=float), (n_variants,))
                               for x in pair], axis=-1) for pair in local], axis=-2)


# The dyads' constants from their bodies' local coordinates (..., 2): written once, elementwise,
# on one body (floats) or on V variants of it at once (:func:`chain_at`).

def linear_coefficients(li, lj, lk):
    """(alpha, beta) of a point at lk from the known points at li, lj of one body:
    p = p_i + alpha d + beta perp(d), d = p_j - p_i; the complex quotient (lk - li) / (lj - li),
    divided as CPython divides complex numbers (Smith's method)."""
    ar, ai = lk[..., 0] - li[..., 0], lk[..., 1] - li[..., 1]
    br, bi = lj[..., 0] - li[..., 0], lj[..., 1] - li[..., 1]
    big = np.abs(br) >= np.abs(bi)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(big, bi / br, br / bi)
        denom = np.where(big, br + bi * ratio, br * ratio + bi)
        alpha = np.where(big, (ar + ai * ratio) / denom, (ar * ratio + ai) / denom)
        beta = np.where(big, (ai - ar * ratio) / denom, (ai * ratio - ar) / denom)
    return _plain(alpha), _plain(beta)


def angle_arm(la, lb, lc, lk):
    """(wx, wy): the arm from the pin at lc to lk in the frame of an angle driver from la to lb
    (the body turned so that the driver's direction is the x axis)."""
    phi0 = np.arctan2(lb[..., 1] - la[..., 1], lb[..., 0] - la[..., 0])
    c0, s0 = np.cos(-phi0), np.sin(-phi0)
    rx, ry = lk[..., 0] - lc[..., 0], lk[..., 1] - lc[..., 1]
    return _plain(c0 * rx - s0 * ry), _plain(s0 * rx + c0 * ry)


def circle_radius(lc, lp):
    """The radius of the circle a body pinned at lc draws with its point at lp."""
    return _plain(np.hypot(lp[..., 0] - lc[..., 0], lp[..., 1] - lc[..., 1]))


def _plain(x):
    """A float for one body, the (V,) array for variants."""
    return float(x) if np.ndim(x) == 0 else x


def chain_at(chain: DyadChain, bodies: list[Body]):
    """The chain's dyads with the constants of V variants' bodies (:func:`bodies_of` with
    their rows): ``(chain, same (V,) bool)``, each constant a (V,) array, ``same`` True where
    the variant's own :func:`decompose` takes these very dyads (each choice the greedy
    placement made from the numbers, made alike: a body's frame pair still apart, the pair
    chosen as the farthest still the farthest, a circle's radius still positive)."""
    by_name = {b.name: b for b in bodies}
    n_variants = max([b.local.shape[0] for b in bodies if b.local.ndim == 3] + [1])
    same = np.ones(n_variants, dtype=bool)
    steps = []
    for st in chain.steps:
        if st.kind == "linear":
            name, i, j, by_distance = st.source
            local = by_name[name].local
            li, lj = local[..., i, :], local[..., j, :]
            same &= np.hypot(*np.moveaxis(lj - li, -1, 0)) != 0.0
            if by_distance:
                same &= _still_farthest(local, [k for k, p in enumerate(by_name[name].points)
                                                if p not in st.targets], i, j)
            ab = [linear_coefficients(li, lj, local[..., k, :]) for k in st.local_targets]
            steps.append(dataclasses.replace(st, ab=ab))
        elif st.kind == "angle":
            name, a, b, c = st.source
            local = by_name[name].local
            w = [angle_arm(local[..., a, :], local[..., b, :], local[..., c, :], local[..., k, :])
                 for k in st.local_targets]
            steps.append(dataclasses.replace(st, w=w))
        elif st.kind in ("circles", "circle_line"):
            radii = []
            for src, r in zip(st.source, (st.r1, st.r2)):
                if src is None:
                    radii.append(r)
                    continue
                name, c, p = src
                local = by_name[name].local
                radius = circle_radius(local[..., c, :], local[..., p, :])
                same &= radius > 0
                radii.append(radius)
            steps.append(dataclasses.replace(st, r1=radii[0], r2=radii[1] if len(radii) > 1 else st.r2))
        else:
            steps.append(st)
    return DyadChain(chain.model, steps, chain.reason), same


def _still_farthest(local, known: list[int], i: int, j: int):
    """(V,) True where the pair (i, j) of known points is still the one ``max`` picks among
    (distance, x, y) of every known pair (as :meth:`_Placer.by_two_known_points` does)."""
    def dist(x, y):
        d = local[..., x, :] - local[..., y, :]
        return np.hypot(d[..., 0], d[..., 1])

    chosen = dist(i, j)
    ok = np.ones(np.shape(chosen), dtype=bool)
    for x in known:
        for y in known:
            if x < y and (x, y) != (i, j):
                other = dist(x, y)
                ok &= (chosen > other) | ((chosen == other) & ((i, j) > (x, y)))
    return ok


def decompose(model: Model) -> DyadChain:
    """Return the scene's closed-form chain (``DyadChain.ok`` False with a reason when none exists).

    Greedy: repeatedly place whatever can be placed (bodies with two known points, bodies
    turned by an angle driver, points with two usable constraints) until every moving point is
    known. Branch signs are left at +1; :func:`set_branches` takes them from a configuration.
    """
    placer = _Placer(model)
    while not placer.known.all() and (placer.by_two_known_points() or placer.by_angle_driver()
                                      or placer.one_point_by_two_constraints()):
        pass
    if not placer.known.all():
        left = [model.point_names[p] for p in range(model.n_points) if not placer.known[p]]
        motors = [model.scene.drivers[j].name for j in range(model.n_drivers)
                  if model.drv_kind[j] == eq.RELATIVE and not placer.used_driver[j]]
        why = (f"the dyads do not take a motor between links (relative_to: "
               f"{', '.join(motors)})" if motors else "a loop that needs simultaneous solution")
        return DyadChain(model, placer.steps, f"no closed-form dyad places point(s) "
                         f"{', '.join(left)} ({why})")
    if not all(placer.used_driver):
        left = [model.scene.drivers[j].name for j, used in enumerate(placer.used_driver) if not used]
        return DyadChain(model, placer.steps,
                         f"driver(s) {', '.join(left)} do not fit a closed-form dyad")
    return DyadChain(model, placer.steps)


class _Placer:
    """The state of :func:`decompose`: which points are known, which constraints are used, the
    dyads so far; one method per rule, each returning whether it placed anything."""

    def __init__(self, model: Model):
        self.model = model
        self.known = np.array(model.fixed, dtype=bool).copy()
        self.bodies = [b for b in bodies_of(model) if not all(self.known[p] for p in b.points)]
        self.sliders_fixed = [(int(p), Line("fixed", o=tuple(map(float, c)), t=(float(n[1]), float(-n[0]))))
                              for p, c, n in zip(model.sfix_p, model.sfix_c, model.sfix_n)]
        self.sliders_moving = [(int(p), int(d), int(e))
                               for p, d, e in zip(model.smov_p, model.smov_d, model.smov_e)]
        self.used_fixed = [False] * len(self.sliders_fixed)
        self.used_moving = [False] * len(self.sliders_moving)
        self.used_driver = [False] * model.n_drivers
        self.steps: list[Dyad] = []

    def known_of(self, b: Body) -> list[int]:
        return [k for k, p in enumerate(b.points) if self.known[p]]

    def by_two_known_points(self) -> bool:
        """Rule 1: a body with two known points gives the rest by local coordinates."""
        progress = False
        for b in self.bodies:
            kk = self.known_of(b)
            if not 2 <= len(kk) < len(b.points):
                continue
            if 0 in kk and 1 in kk:
                i, j = 0, 1
            else:  # the known pair farthest apart in the body
                pairs = [(np.hypot(*(b.local[x] - b.local[y])), x, y) for x in kk for y in kk if x < y]
                _, i, j = max(pairs)
            li, lj = b.local[i], b.local[j]
            if abs(complex(*(lj - li))) == 0.0:
                continue
            tg, ab, ks = [], [], []
            for k, p in enumerate(b.points):
                if not self.known[p]:
                    tg.append(p)
                    ks.append(k)
                    ab.append(linear_coefficients(li, lj, b.local[k]))
            self.steps.append(Dyad("linear", tg, i=b.points[i], j=b.points[j], ab=ab,
                                   source=(b.name, i, j, not (0 in kk and 1 in kk)),
                                   local_targets=ks))
            self.known[tg] = True
            progress = True
        return progress

    def by_angle_driver(self) -> bool:
        """Rule 2: an angle driver turns a body pinned at one known point."""
        model, progress = self.model, False
        for jd in range(model.n_drivers):
            if self.used_driver[jd] or model.drv_kind[jd] != eq.ANGLE:
                continue
            a, bpt = int(model.drv_a[jd]), int(model.drv_b[jd])
            for b in self.bodies:
                kk = self.known_of(b)
                if not (a in b.points and bpt in b.points) or len(kk) != 1:
                    continue
                ia_, ib_ = b.points.index(a), b.points.index(bpt)
                ck = kk[0]
                tg, ws, ks = [], [], []
                for k, p in enumerate(b.points):
                    if not self.known[p]:
                        tg.append(p)
                        ks.append(k)
                        ws.append(angle_arm(b.local[ia_], b.local[ib_], b.local[ck], b.local[k]))
                self.steps.append(Dyad("angle", tg, c=b.points[ck], driver=jd, w=ws,
                                       source=(b.name, ia_, ib_, ck), local_targets=ks))
                self.known[tg] = True
                self.used_driver[jd] = True
                progress = True
                break
        return progress

    def one_point_by_two_constraints(self) -> bool:
        """Rule 3: one point on two known circles (pinned bodies) and/or lines (guides, driven
        coordinates); bodies may then have two known points, so rule 1 goes first again."""
        for p in range(self.model.n_points):
            if self.known[p]:
                continue
            circles, lines = self._circles_of(p), self._lines_of(p)
            if len(lines) >= 2:
                st = Dyad("lines", [p], line1=lines[0][0], line2=lines[1][0])
                use = lines[:2]
            elif len(lines) == 1 and circles:
                (c1, r1, j1, src1), = circles[:1]
                st = Dyad("circle_line", [p], c1=c1, r1=r1, r1_driver=j1, line1=lines[0][0],
                          source=(src1,))
                use = lines[:1] + [(None, "d", j1)] * (j1 >= 0)
            elif len(circles) >= 2:
                (c1, r1, j1, src1), (c2, r2, j2, src2) = circles[:2]
                st = Dyad("circles", [p], c1=c1, r1=r1, c2=c2, r2=r2, r1_driver=j1, r2_driver=j2,
                          source=(src1, src2))
                use = [(None, "d", j) for j in (j1, j2) if j >= 0]
            else:
                continue
            for _, kind, k in use:
                {"f": self.used_fixed, "m": self.used_moving, "d": self.used_driver}[kind][k] = True
            self.steps.append(st)
            self.known[p] = True
            return True
        return False

    def _circles_of(self, p: int) -> list[tuple[int, float, int, tuple | None]]:
        """(centre, radius, -1, (body, centre's, p's local index)) of each body through p
        pinned at one known point, and (centre, 0.0, driver, None) of each unused distance
        driver from a known point to p (distinct centres)."""
        circles = []
        for b in self.bodies:
            if p in b.points:
                kk = self.known_of(b)
                if len(kk) == 1:
                    c = b.points[kk[0]]
                    kp = b.points.index(p)
                    r = circle_radius(b.local[kk[0]], b.local[kp])
                    if r > 0 and all(c != cc for cc, _, _, _ in circles):
                        circles.append((c, r, -1, (b.name, kk[0], kp)))
        model = self.model
        for jd in np.flatnonzero(model.drv_kind == eq.DISTANCE):
            ends = (int(model.drv_a[jd]), int(model.drv_b[jd]))
            if self.used_driver[jd] or p not in ends:
                continue
            c = ends[1] if ends[0] == p else ends[0]
            if self.known[c] and all(c != cc for cc, _, _, _ in circles):
                circles.append((c, 0.0, int(jd), None))
        return circles

    def _lines_of(self, p: int) -> list[tuple[Line, str, int]]:
        """(line, kind, index) of each unused guide or driven coordinate p lies on."""
        model, lines = self.model, []
        for k, (pp, ln) in enumerate(self.sliders_fixed):
            if pp == p and not self.used_fixed[k]:
                lines.append((ln, "f", k))
        for k, (pp, d, e) in enumerate(self.sliders_moving):
            if pp == p and not self.used_moving[k] and self.known[d] and self.known[e]:
                lines.append((Line("moving", d=d, e=e), "m", k))
        for jd in range(model.n_drivers):
            if (not self.used_driver[jd] and model.drv_kind[jd] == eq.COORDINATE
                    and int(model.drv_a[jd]) == p):
                ax = int(model.drv_axis[jd])
                lines.append((Line("coord", t=(0.0, 1.0) if ax == 0 else (1.0, 0.0), driver=jd,
                                   axis=ax), "d", jd))
        return lines
