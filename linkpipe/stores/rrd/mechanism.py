"""The mechanism's 2D entities: points, links (bars and plates), actuators, guides, springs,
traces and the velocity and acceleration arrows; each entity one ``send`` for the sweep."""
from __future__ import annotations

import numpy as np
import rerun as rr

from . import style
from .columns import labels_arrow, strips_arrow
from .geometry import arrow_legend, arrow_scales, finite_rows, mechanism_size, outline, point_index, runs


def path_of(*parts) -> str:
    """The entity path of unescaped parts (scene names may hold ``/``, spaces, backslashes):
    Rerun's own escaping (``rr.new_entity_path``), so that distinct names stay distinct."""
    return rr.new_entity_path([str(p) for p in parts])


def log_points(stream, send, result) -> None:
    X = result.position
    ok = finite_rows(X)                                  # (S, P)
    stream.log("mechanism/points", rr.Points2D.from_fields(
        radii=rr.components.Radius.ui_points(4.0), colors=style.POINT,
        show_labels=len(result.point_names) <= style.CROWD,
        draw_order=30.0), static=True)
    if ok.any():
        pos = X.reshape(-1, 2) if ok.all() else X[ok]  # all finite: no masked copy
        send("mechanism/points",
             rr.Points2D.columns(positions=np.asarray(pos, dtype=np.float32),
                                 labels=labels_arrow(result.point_names, ok))
             .partition(ok.sum(axis=1)))
    fixed = [i for i, p in enumerate(result.scene.points) if p.fixed]
    if fixed:
        ground = np.array([[result.scene.points[i].x, result.scene.points[i].y] for i in fixed])
        stream.log("mechanism/ground", rr.Points2D(
            ground, radii=rr.components.Radius.ui_points(8.0), colors=style.GROUND, draw_order=25.0),
            static=True)


def log_links(stream, send, result) -> None:
    """Each link in its own muted colour (:func:`.style.link_colour`, the colour of its
    ``link_angle`` series too; never an arrow's hue): a bar between its two points, a plate (3 or more points) as a closed polygon
    that does not cross itself (:func:`.geometry.outline`)."""
    for j, link in enumerate(result.scene.links):
        k = outline(result, point_index(result, link.points))
        send_strips(stream, send, path_of("mechanism", "links", link.name), result.position[:, k],
                    radii=rr.components.Radius.ui_points(3.0), colors=style.link_colour(j),
                    draw_order=20.0)


def log_actuators(stream, send, result) -> None:
    """``mechanism/actuators/<driver>``: each ``distance`` driver (a linear actuator, which is
    not a link) as a wide grey bar between its two pins."""
    for driver in result.scene.drivers:
        if driver.kind == "distance":
            send_strips(stream, send, path_of("mechanism", "actuators", driver.name),
                        result.position[:, point_index(result, driver.points)],
                        radii=rr.components.Radius.ui_points(4.5), colors=style.ACTUATOR,
                        draw_order=18.0)


def send_strips(stream, send, entity: str, strips: np.ndarray, **style_) -> None:
    """Log one strip per step from ``strips`` (S, n, 2); steps with a NaN get none (cleared)."""
    ok = finite_rows(strips.reshape(len(strips), -1))
    stream.log(entity, rr.LineStrips2D.from_fields(**style_), static=True)
    if ok.any():
        send(entity, rr.LineStrips2D.columns(strips=strips_arrow(strips if ok.all() else strips[ok]))
             .partition(ok.astype(int)))


def log_guides(stream, send, result) -> None:
    margin = 0.1 * mechanism_size(result)
    for slider in result.scene.sliders:
        (k,) = point_index(result, [slider.point])
        P = result.position[:, k]
        entity = path_of("mechanism", "guides", slider.name)
        look = dict(radii=rr.components.Radius.ui_points(1.5), colors=style.GUIDE, draw_order=5.0)
        if not slider.moving:
            t0 = np.asarray(slider.through, float)
            d = np.asarray(slider.direction, float)
            d = d / np.linalg.norm(d)
            s = (P - t0) @ d
            s = s[np.isfinite(s)]
            lo, hi = (s.min(), s.max()) if len(s) else (0.0, 0.0)
            segment = t0 + np.outer([lo - margin, hi + margin], d)
            stream.log(entity, rr.LineStrips2D([segment], **look), static=True)
            continue
        D, E = (result.position[:, i] for i in point_index(result, slider.line_points))
        length = np.linalg.norm(E - D, axis=1, keepdims=True)
        d = (E - D) / np.where(length > 0, length, np.nan)
        s = np.stack([np.zeros(len(P)), length[:, 0], np.einsum("ij,ij->i", P - D, d)], axis=1)
        ends = np.stack([s.min(axis=1) - margin, s.max(axis=1) + margin], axis=1)  # (S, 2)
        send_strips(stream, send, entity, D[:, None, :] + ends[:, :, None] * d[:, None, :], **look)


def log_springs(stream, send, result) -> None:
    """Log ``mechanism/springs/<spring>`` (an addition to the contract): a line per step."""
    if not result.spring_names:
        return
    for spring in result.scene.springs:
        send_strips(stream, send, path_of("mechanism", "springs", spring.name),
                    result.position[:, point_index(result, spring.between)],
                    radii=rr.components.Radius.ui_points(1.0), colors=style.SPRING, draw_order=15.0)


def log_traces(stream, result) -> None:
    for name in result.scene.outputs.trace:
        (k,) = point_index(result, [name])
        pieces = runs(result.position[:, k])
        if pieces:
            stream.log(path_of("mechanism", "trace", name), rr.LineStrips2D(
                pieces, radii=rr.components.Radius.ui_points(1.0), colors=style.TRACE,
                labels=[f"trace {name}"] * len(pieces), show_labels=False, draw_order=10.0),
                static=True)


def log_vectors(stream, send, result) -> None:
    """Velocity and acceleration arrows, one scale per quantity.

    Each arrow's label names its scale but is not drawn (a velocity and an acceleration at one
    point, often near parallel, would put their labels on top of each other): the viewer shows
    it on hover, and the 2D view's title gives the scales (see :func:`.geometry.arrow_legend`).
    """
    scales = arrow_scales(result)
    for quantity, scale in scales.items():
        data = getattr(result, quantity)
        for name in result.scene.outputs.vectors:
            (k,) = point_index(result, [name])
            origins, vectors = result.position[:, k], data[:, k]
            ok = finite_rows(origins) & finite_rows(vectors)
            entity = path_of("mechanism", quantity, name)
            stream.log(entity, rr.Arrows2D.from_fields(
                labels=[f"{quantity[0]} {name} ({arrow_legend(result, quantity)})"],
                colors=style.VECTOR_COLORS[quantity], show_labels=False,
                radii=rr.components.Radius.ui_points(1.5), draw_order=40.0), static=True)
            if ok.any():
                if not ok.all():
                    origins, vectors = origins[ok], vectors[ok]
                send(entity, rr.Arrows2D.columns(origins=np.asarray(origins, dtype=np.float32),
                                                 vectors=np.asarray(vectors * scale, dtype=np.float32))
                     .partition(ok.astype(int)))
