"""The optional safety filter: a control barrier function on a point ahead of the axle (design §19).

``safety.filter = "cbf"`` (off by default: the paper has none) passes each follower's kinematic
command ``(υ_cmd, ω_cmd)`` of eq. 31 through a small QP before the torque law (eqs. 38–39), the
Robotarium's construction (Wang, Ames, Egerstedt 2017): the point ``p = (x + l cos θ, y + l sin θ)``
a look-ahead ``l`` ahead of the axle moves as a single integrator, ``ṗ = u = J(θ) (υ, ω)`` with
``J = [[cos θ, −l sin θ], [sin θ, l cos θ]]`` (invertible for ``l > 0``), and each follower solves

    min |u − û|²  s.t.  −2 (p_i − p_j) · u ≤ (γ / 2) h_ij  for every other robot j,
                        −2 (p_i − q_k) · u ≤ γ h_ik        for every obstacle k,

with ``û = J (υ_cmd, ω_cmd)``, ``h_ij = |p_i − p_j|² − (r_i + r_j + d + 2 l)²`` (``r``: the robots'
footprint radii, ``d``: ``safety.distance``; ``2 l`` because the points, not the axles, are kept
apart), ``q_k`` the obstacle's nearest point (a cylinder's centre with its radius added to the
distance), each robot taking half of a pair's constraint (the decentralised split: the other does
the other half). Only neighbours within ``range`` m enter. Two robots meeting head-on or side by
side stop each other symmetrically (the filter's known deadlock); the right-hand rule breaks it:
where the nominal command violates a pair's constraint, ``û`` is first turned towards the right
of the other robot by ``pass_right`` × its speed (``û += ε |û| R(−90°) (p_i − p_j)/|p_i − p_j|``;
0: the pure minimal QP). Obstacles get no such turn (the QP already slides along them). The QP
is solved by Hildreth's dual coordinate ascent (exact after one sweep with one active constraint;
to ``1e-9`` otherwise, at most :data:`HILDRETH_SWEEPS` sweeps), compiled, so both engines run it.
"""

from __future__ import annotations

from math import cos, hypot, sin, sqrt

from bioform_mj.core.equations import njit

HILDRETH_SWEEPS = 200
#: a constraint violated by more than this after :data:`HILDRETH_SWEEPS` sweeps: the QP has no solution
#: (robots or obstacles closer than the filter can keep apart), counted per follower (issue 28)
CBF_RESIDUAL = 1e-6


@njit
def cbf_filter(i, v, w, pose, rad, obst, par, A, b, lam):
    """The filtered ``(υ, ω)`` of follower ``i`` (see the module docstring).

    ``pose`` (n, 3) every robot's ``[x, y, θ]``; ``rad`` (n,) footprint radii m; ``obst`` (m, 7)
    rows ``[shape (0 box, 1 cylinder), x, y, s0, s1, s2, yaw]`` (:func:`bioform_mj.formation.obstacles.to_rows`);
    ``par`` (4,) or (5,) ``[l m, γ 1/s, d m, range m, pass_right]``; scratch ``A`` (K, 2), ``b``,
    ``lam`` (K,), K ≥ n + m. On return ``lam[K - 1]`` (a slot no constraint uses: at most n − 1 + m
    are active) holds the QP's largest remaining violation, 0 when it was solved; above
    :data:`CBF_RESIDUAL` the QP had no solution and the command returned is the last iterate.
    """
    la, gam, dist, reach = par[0], par[1], par[2], par[3]
    eps = par[4] if par.shape[0] > 4 else 0.0
    n0 = 0.0
    n1 = 0.0
    c = cos(pose[i, 2])
    s = sin(pose[i, 2])
    px = pose[i, 0] + la * c
    py = pose[i, 1] + la * s
    u0 = c * v - la * s * w
    u1 = s * v + la * c * w
    k = 0
    n = pose.shape[0]
    for j in range(n):
        if j == i:
            continue
        dx = px - (pose[j, 0] + la * cos(pose[j, 2]))
        dy = py - (pose[j, 1] + la * sin(pose[j, 2]))
        D = rad[i] + rad[j] + dist + 2.0 * la
        d2 = dx * dx + dy * dy
        if sqrt(d2) > D + reach:
            continue
        A[k, 0] = -2.0 * dx
        A[k, 1] = -2.0 * dy
        b[k] = 0.5 * gam * (d2 - D * D)
        if eps > 0.0 and A[k, 0] * u0 + A[k, 1] * u1 > b[k]:  # the right-hand rule (module docstring)
            sp = hypot(u0, u1) * eps / max(sqrt(d2), 1e-12)
            n0 += sp * dy
            n1 -= sp * dx
        k += 1
    for o in range(obst.shape[0]):
        if obst[o, 0] == 1.0:  # cylinder: its centre, its radius added
            dx = px - obst[o, 1]
            dy = py - obst[o, 2]
            D = obst[o, 3] + rad[i] + dist + la
        else:  # box: its nearest point (the centre's direction from inside)
            cy_ = cos(obst[o, 6])
            sy_ = sin(obst[o, 6])
            rx = cy_ * (px - obst[o, 1]) + sy_ * (py - obst[o, 2])
            ry = -sy_ * (px - obst[o, 1]) + cy_ * (py - obst[o, 2])
            qx = min(max(rx, -obst[o, 3]), obst[o, 3])
            qy = min(max(ry, -obst[o, 4]), obst[o, 4])
            ex, ey = rx - qx, ry - qy
            if ex == 0.0 and ey == 0.0:
                ex, ey = rx, ry
            dx = cy_ * ex - sy_ * ey
            dy = sy_ * ex + cy_ * ey
            D = rad[i] + dist + la
        d2 = dx * dx + dy * dy
        if sqrt(d2) > D + reach:
            continue
        A[k, 0] = -2.0 * dx
        A[k, 1] = -2.0 * dy
        b[k] = gam * (d2 - D * D)
        k += 1
    lam[lam.shape[0] - 1] = 0.0
    if k == 0:
        return v, w
    # Hildreth: u = û − Aᵀλ, λ ≥ 0, one coordinate at a time
    x0, x1 = u0 + n0, u1 + n1
    for q in range(k):
        lam[q] = 0.0
    worst = 0.0
    for _ in range(HILDRETH_SWEEPS):
        worst = 0.0
        for q in range(k):
            nn = A[q, 0] * A[q, 0] + A[q, 1] * A[q, 1]
            if nn <= 0.0:
                continue
            viol = A[q, 0] * x0 + A[q, 1] * x1 - b[q]
            new = max(0.0, lam[q] + viol / nn)
            dl = new - lam[q]
            if dl != 0.0:
                lam[q] = new
                x0 -= dl * A[q, 0]
                x1 -= dl * A[q, 1]
            worst = max(worst, viol)
        if worst <= 1e-9:
            break
    if worst > 1e-9:  # no solution within the sweeps: said through the free slot (docstring)
        lam[lam.shape[0] - 1] = worst
    return c * x0 + s * x1, (-s * x0 + c * x1) / la
