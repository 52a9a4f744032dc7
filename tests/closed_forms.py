"""Closed-form kinematics of the textbook mechanisms, independent of linkpipe's solver.

Four-bar: Norton, Design of Machinery, eqs. 4.10 (position), 6.18 (velocity), 7.12
(acceleration), with ground O2 at the origin and O4 at (d, 0). Slider-crank with offset e:
x_B = a cos(t) + sqrt(b^2 - (a sin(t) - e)^2), differentiated by hand.
All functions take arrays of crank angles (rad) and return arrays, step axis first.
"""
import numpy as np


def fourbar(a, b, c, d, theta2, omega2, alpha2, branch=+1, coupler_uv=(0.0, 0.0)):
    """Return dict of A, B, P positions/velocities/accelerations (S, 2) and theta3/theta4/omegas."""
    t2 = np.asarray(theta2, float)
    A = np.stack([a * np.cos(t2), a * np.sin(t2)], -1)
    O4 = np.array([d, 0.0])
    # B: intersection of circle(A, b) and circle(O4, c); branch +1 = left of A->O4
    v = O4 - A
    dist = np.linalg.norm(v, axis=-1)
    along = (b**2 - c**2 + dist**2) / (2 * dist)
    h = np.sqrt(b**2 - along**2)
    e = v / dist[:, None]
    ep = np.stack([-e[:, 1], e[:, 0]], -1)
    B = A + along[:, None] * e + branch * h[:, None] * ep
    t3 = np.arctan2(B[:, 1] - A[:, 1], B[:, 0] - A[:, 0])
    t4 = np.arctan2(B[:, 1] - O4[1], B[:, 0] - O4[0])
    w2, al2 = omega2, alpha2
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
    VA = a * w2 * perp(e2)
    AA = a * al2 * perp(e2) - a * w2**2 * e2
    VB = c * w4[:, None] * perp(e4)
    AB = c * al4[:, None] * perp(e4) - c * (w4**2)[:, None] * e4
    u, vv = coupler_uv
    r = u * e3 + vv * perp(e3)
    P = A + r
    VP = VA + w3[:, None] * perp(r)
    AP = AA + al3[:, None] * perp(r) - (w3**2)[:, None] * r
    return dict(A=A, B=B, P=P, VA=VA, VB=VB, VP=VP, AA=AA, AB=AB, AP=AP,
                theta3=t3, theta4=t4, omega3=w3, omega4=w4, alpha3=al3, alpha4=al4)


def slider_crank(a, b, e, theta, omega, alpha):
    """Return A, B positions, velocities, accelerations (S, 2) of an offset slider-crank."""
    t = np.asarray(theta, float)
    s, c = np.sin(t), np.cos(t)
    h = a * s - e
    r = np.sqrt(b**2 - h**2)
    x = a * c + r
    hd = a * c * omega
    hdd = -a * s * omega**2 + a * c * alpha
    xd = -a * s * omega - h * hd / r
    xdd = -a * c * omega**2 - a * s * alpha - (hd**2 + h * hdd) / r - h**2 * hd**2 / r**3
    z = np.zeros_like(t)
    A = np.stack([a * c, a * s], -1)
    VA = np.stack([-a * s * omega, a * c * omega], -1)
    AA = np.stack([-a * c * omega**2 - a * s * alpha, -a * s * omega**2 + a * c * alpha], -1)
    B = np.stack([x, z + e], -1)
    VB = np.stack([xd, z], -1)
    AB = np.stack([xdd, z], -1)
    return dict(A=A, B=B, VA=VA, VB=VB, AA=AA, AB=AB)
