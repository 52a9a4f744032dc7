"""How a scene decomposes into closed-form dyads (the fast path's plan), found once from the
scene's graph: which points each dyad places from which known points, circles and lines."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model import Model
from ..model import equations as eq


@dataclass
class Body:
    """One link as a rigid body: its point indices and their local coordinates (n, 2)."""

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


def bodies_of(model: Model) -> list[Body]:
    """Return every link as a body with local coordinates (a at 0, b at (L, 0), others (u, v))."""
    scene = model.scene
    names = model.point_names
    index = {n: i for i, n in enumerate(names)}
    X0 = model.start_position
    loc = {(int(a), int(b), int(p)): (float(u), float(v)) for a, b, p, u, v in zip(
        model.loc_a, model.loc_b, model.loc_p, model.loc_u, model.loc_v)}
    out = []
    for link in scene.links:
        pts = [index[p] for p in link.points]
        ia, ib = pts[0], pts[1]
        d0 = X0[ib] - X0[ia]
        L0 = float(np.hypot(*d0))
        L = float(link.length) if link.length is not None else L0
        e = d0 / L0
        ep = np.array([-e[1], e[0]])
        local = [(0.0, 0.0), (L, 0.0)]
        for ip in pts[2:]:
            if (ia, ib, ip) in loc:
                local.append(loc[(ia, ib, ip)])
            elif link.points[pts.index(ip)] in link.local:
                u, v = link.local[link.points[pts.index(ip)]]
                local.append((float(u), float(v)))
            else:
                r = X0[ip] - X0[ia]
                local.append((float(r @ e), float(r @ ep)))
        out.append(Body(link.name, pts, np.array(local, dtype=float)))
    return out


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
        return DyadChain(model, placer.steps, f"no closed-form dyad places point(s) "
                         f"{', '.join(left)} (a loop that needs simultaneous solution)")
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
            dl = complex(*(lj - li))
            if abs(dl) == 0.0:
                continue
            tg, ab = [], []
            for k, p in enumerate(b.points):
                if not self.known[p]:
                    z = complex(*(b.local[k] - li)) / dl
                    tg.append(p)
                    ab.append((z.real, z.imag))
            self.steps.append(Dyad("linear", tg, i=b.points[i], j=b.points[j], ab=ab))
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
                la, lb = b.local[b.points.index(a)], b.local[b.points.index(bpt)]
                phi0 = np.arctan2(*(lb - la)[::-1])
                c0, s0 = np.cos(-phi0), np.sin(-phi0)
                ck = kk[0]
                tg, ws = [], []
                for k, p in enumerate(b.points):
                    if not self.known[p]:
                        r = b.local[k] - b.local[ck]
                        tg.append(p)
                        ws.append((float(c0 * r[0] - s0 * r[1]), float(s0 * r[0] + c0 * r[1])))
                self.steps.append(Dyad("angle", tg, c=b.points[ck], driver=jd, w=ws))
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
                (c1, r1, j1), = circles[:1]
                st = Dyad("circle_line", [p], c1=c1, r1=r1, r1_driver=j1, line1=lines[0][0])
                use = lines[:1] + [(None, "d", j1)] * (j1 >= 0)
            elif len(circles) >= 2:
                (c1, r1, j1), (c2, r2, j2) = circles[:2]
                st = Dyad("circles", [p], c1=c1, r1=r1, c2=c2, r2=r2, r1_driver=j1, r2_driver=j2)
                use = [(None, "d", j) for j in (j1, j2) if j >= 0]
            else:
                continue
            for _, kind, k in use:
                {"f": self.used_fixed, "m": self.used_moving, "d": self.used_driver}[kind][k] = True
            self.steps.append(st)
            self.known[p] = True
            return True
        return False

    def _circles_of(self, p: int) -> list[tuple[int, float, int]]:
        """(centre, radius, -1) of each body through p pinned at one known point, and (centre,
        0.0, driver) of each unused distance driver from a known point to p (distinct centres)."""
        circles = []
        for b in self.bodies:
            if p in b.points:
                kk = self.known_of(b)
                if len(kk) == 1:
                    c = b.points[kk[0]]
                    r = float(np.hypot(*(b.local[b.points.index(p)] - b.local[kk[0]])))
                    if r > 0 and all(c != cc for cc, _, _ in circles):
                        circles.append((c, r, -1))
        model = self.model
        for jd in np.flatnonzero(model.drv_kind == eq.DISTANCE):
            ends = (int(model.drv_a[jd]), int(model.drv_b[jd]))
            if self.used_driver[jd] or p not in ends:
                continue
            c = ends[1] if ends[0] == p else ends[0]
            if self.known[c] and all(c != cc for cc, _, _ in circles):
                circles.append((c, 0.0, int(jd)))
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
