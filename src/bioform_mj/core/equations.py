"""The paper's equations, each written once, as small functions on scalars.

This module is the single source of every equation of the control law and of the
ideal plant (docs/design.md §2 maps each equation to its function here). Each function
takes floats and returns a float or a tuple of floats; it uses only ``+ − × ÷``,
comparisons, ``min``/``max``/``abs`` and the names ``cos, sin, exp, atan2, hypot, sqrt``
imported below. That restricted form is what lets one source serve three engines:

* the compiled CPU engine: :func:`equation` compiles each function with numba
  (cached on disk, IEEE semantics, no fastmath), and the kernels in ``kernel.py`` and
  in each plant call them inside their loops;
* a readable Python path for debugging: run with ``NUMBA_DISABLE_JIT=1`` and the very
  same functions execute as plain Python (``math`` functions, libm);
* a batch engine can re-read the plain source (:data:`EQUATIONS`) and compile it for
  another target (e.g. Warp functions), instead of a third copy.

Vectorised numpy forms of the same equations live only in ``tests/oracle.py``, as
independent oracles compared with stated tolerances.
"""

from __future__ import annotations

from collections.abc import Callable
from math import atan2, cos, exp, hypot, pi, sin, sqrt  # noqa: F401  (the names equations may use)

try:  # numba is a dependency; without it everything still runs as plain Python
    import numba

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover
    numba = None
    HAVE_NUMBA = False

#: name -> plain Python function of every equation (for engines that compile the source elsewhere)
EQUATIONS: dict[str, Callable] = {}


def _cache_dir() -> str:
    """Where numba caches our kernels: a folder keyed by the source of every module that holds
    kernels (:func:`bioform_mj.core.codehash.kernel_hash`). numba invalidates a cached function only when
    its *own* file changes, not when a function it calls (and inlines) from another file does; a plant's
    loop kernel would otherwise keep an old control law after an upgrade. ``$NUMBA_CACHE_DIR`` (if set) is
    the parent."""
    import os

    from bioform_mj.core.codehash import kernel_hash

    base = os.environ.get("NUMBA_CACHE_DIR") or os.path.join(os.path.expanduser("~"), ".cache", "bioform_mj")
    return os.path.join(base, "numba-" + kernel_hash())


#: where the kernels are cached when the usual folder cannot be written, or that nothing is ("" normally; the CLI
#: says it in a ``warning:`` line, Python code gets a :class:`~bioform_mj.core.errors.CacheWarning`)
CACHE_NOTE = ""
_CACHE = HAVE_NUMBA
if HAVE_NUMBA:
    import os as _os
    import warnings as _warnings

    from bioform_mj.core.errors import CacheWarning
    from bioform_mj.core.jitcache import guard as _guard_cache
    from bioform_mj.core.jitcache import install as _install_locator
    from bioform_mj.core.jitcache import writable_cache_dir

    _dir = _cache_dir()
    _dir, CACHE_NOTE = writable_cache_dir(_dir, _os.path.basename(_dir))
    if _dir is None:
        _CACHE = False  # numba.njit(cache=True) without a writable folder raises at the decorator
    else:
        numba.config.CACHE_DIR = _dir
    if CACHE_NOTE:
        _warnings.warn(CACHE_NOTE, CacheWarning, stacklevel=2)
    _install_locator()  # the same source anywhere (a second clone) reuses the cache (core/jitcache.py)


def njit(fn: Callable | None = None, *, inline: bool = False) -> Callable:
    """numba-compile ``fn`` (cached on disk, no fastmath: IEEE results); identity without numba.
    ``@njit(inline=True)``: numba inlines ``fn`` into the compiled functions that call it (its arguments are
    then not passed: no reference counts taken on its arrays at each call, see ``envs/fast.py``)."""
    if fn is None:
        return lambda f: njit(f, inline=inline)
    if not HAVE_NUMBA:  # pragma: no cover
        return fn
    opts = {"inline": "always"} if inline else {}
    return _guard_cache(numba.njit(cache=_CACHE, nogil=True, error_model="numpy", **opts)(fn))


def equation(fn: Callable) -> Callable:
    """Register ``fn`` as an equation (plain source kept in :data:`EQUATIONS`) and compile it."""
    EQUATIONS[fn.__name__] = fn
    return njit(fn)


# ----------------------------------------------------------------------------- helpers
@equation
def wrap(a: float) -> float:
    """Angle ``a`` (rad) wrapped to (−π, π] (design §3: every heading difference is wrapped)."""
    return pi - (pi - a) % (2.0 * pi)


@equation
def sat(x: float, phi: float) -> float:
    """``sgn(x)`` for ``phi == 0`` (the paper), else the boundary layer ``clip(x/phi, −1, 1)``.

    ``phi`` has the units of ``x``. In discrete time a term ``−k sat(x/φ)`` is stable only
    while ``k·dt/φ < 2`` (design §4).
    """
    if phi == 0.0:
        if x > 0.0:
            return 1.0
        if x < 0.0:
            return -1.0
        return 0.0
    return min(max(x / phi, -1.0), 1.0)


@equation
def clip(x: float, lo: float, hi: float) -> float:
    """``x`` limited to ``[lo, hi]``."""
    return min(max(x, lo), hi)


# -------------------------------------------------------------- estimator (eqs. 12–13)
@equation
def estimator_euler(
    px: float,
    py: float,
    pth: float,
    v: float,
    w: float,
    dpx: float,
    dpy: float,
    dpth: float,
    dv: float,
    dw: float,
    dt: float,
) -> tuple[float, float, float, float, float]:
    """One explicit-Euler step of follower ``i``'s estimator from its rates (:func:`estimator_rates`,
    computed once per control step): ``(px, py, pth, v, w) + dt · rates`` (``P_ir`` m, m, rad;
    ``[υ_ir, ω_ir]``), ``pth`` wrapped."""
    return px + dt * dpx, py + dt * dpy, wrap(pth + dt * dpth), v + dt * dv, w + dt * dw


@equation
def estimator_rates(
    pth: float,
    v: float,
    w: float,
    ep0: float,
    ep1: float,
    ep2: float,
    ev0: float,
    ev1: float,
    kx: float,
    ky: float,
    kth: float,
    ka0: float,
    ka1: float,
    kb0: float,
    kb1: float,
    phi0: float,
    phi1: float,
) -> tuple[float, float, float, float, float]:
    """Right-hand sides of eqs. 12–13 of follower ``i``'s distributed estimator: ``(ẋ_ir, ẏ_ir, θ̇_ir,
    υ̇_ir, ω̇_ir)`` (m/s, m/s, rad/s, m/s², rad/s²).

    ``(pth, v, w)`` = ``θ_ir, υ_ir, ω_ir``; ``ep*`` the consensus errors ``Σ_j a_ij (P_i − P_j) +
    a_ir (P_i − P_r)`` (heading wrapped), ``ev*`` the same for the velocities. Eq. 12:
    ``Ṗ = [υ cos θ, υ sin θ, ω] − k_p ⊙ P̃``; eq. 13: ``[υ̇, ω̇] = −k_a ⊙ sgn(e_v) − k_b ⊙ e_v``
    (``sgn`` → :func:`sat` with ``phi``). One step of the estimator is :func:`estimator_euler` of these.
    """
    dpx = v * cos(pth) - kx * ep0
    dpy = v * sin(pth) - ky * ep1
    dpth = w - kth * ep2
    dv = -ka0 * sat(ev0, phi0) - kb0 * ev0
    dw = -ka1 * sat(ev1, phi1) - kb1 * ev1
    return dpx, dpy, dpth, dv, dw


# ------------------------------------------------------- kinematic control (eqs. 27–33)
@equation
def slot_reference(
    xr: float, yr: float, thr: float, v: float, w: float, dx: float, dy: float
) -> tuple[float, float, float, float, float]:
    """The reference a follower tracks when its offset ``(dx, dy)`` is in the leader's frame
    (design §4, not in the paper): the slot ``p_s = p_r − R(θ_r) Δ`` moves at
    ``ṗ_s = υ_r h_r + ω_r J R Δ`` (``J``: +90° rotation), not at the leader's velocity, so eq. 31's
    feed-forward takes the slot's own speed ``υ_s = ±|ṗ_s|`` (sign of its component along the
    leader's heading), heading ``θ_s`` (the direction of ``±ṗ_s``) and ``ω_s = ω_r`` (exact while
    ``υ_r, ω_r`` are constant). Returns ``(x_s, y_s, θ_s, υ_s, ω_s)``."""
    c = cos(thr)
    s = sin(thr)
    ox = c * dx - s * dy
    oy = s * dx + c * dy
    px = v * c + w * oy
    py = v * s - w * ox
    sp = hypot(px, py)
    if sp < 1e-9:
        return xr - ox, yr - oy, thr, 0.0, w
    if px * c + py * s < 0.0:
        return xr - ox, yr - oy, atan2(-py, -px), -sp, w
    return xr - ox, yr - oy, atan2(py, px), sp, w


@equation
def formation_offset(dx: float, dy: float, th: float, leader_frame: bool) -> tuple[float, float]:
    """The formation offset ``Δ_i`` in world axes: ``(dx, dy)`` as given (world frame, the paper)
    or, with ``leader_frame``, rotated by the leader's heading ``th`` (rad) so the formation turns
    with its leader (design §4)."""
    if not leader_frame:
        return dx, dy
    c = cos(th)
    s = sin(th)
    return c * dx - s * dy, s * dx + c * dy


@equation
def tracking_error(
    xr: float, yr: float, thr: float, x: float, y: float, th: float, dx: float, dy: float
) -> tuple[float, float, float]:
    """Body-frame tracking error ``[x̃, ỹ, θ̃]`` of eqs. 27–28 (m, m, rad).

    ``(xr, yr, thr)`` the follower's estimate of the leader, ``(x, y, th)`` its pose,
    ``(dx, dy)`` its formation offset (world frame): ``e = P_ir − P_i − Δ_i`` rotated into
    the body frame, ``θ̃`` wrapped.
    """
    ex = xr - x - dx
    ey = yr - y - dy
    c = cos(th)
    s = sin(th)
    return c * ex + s * ey, -s * ex + c * ey, wrap(thr - th)


@equation
def slot_error(
    xr: float,
    yr: float,
    thr: float,
    vr: float,
    wr: float,
    dx: float,
    dy: float,
    x: float,
    y: float,
    th: float,
    leader_frame: bool,
) -> tuple[float, float, float, float, float]:
    """A follower's tracking error (eqs. 27–28) and the velocities its slot moves with.

    ``(xr, yr, thr)``, ``(vr, wr)``: its estimate of the leader's pose and velocities; ``(dx, dy)`` its
    offset (m); ``(x, y, th)`` its pose. World-frame offsets (the paper): :func:`tracking_error` with the
    offset, the slot moving with ``(vr, wr)``; ``leader_frame``: against the slot's own pose and
    velocity (:func:`slot_reference`, design §4), no offset left. Returns ``(x̃, ỹ, θ̃, υ_ref, ω_ref)``.
    """
    px = xr
    py = yr
    pth = thr
    v_ref = vr
    w_ref = wr
    ox = dx
    oy = dy
    if leader_frame:
        px, py, pth, v_ref, w_ref = slot_reference(xr, yr, thr, vr, wr, dx, dy)
        ox = 0.0
        oy = 0.0
    e0, e1, e2 = tracking_error(px, py, pth, x, y, th, ox, oy)
    return e0, e1, e2, v_ref, w_ref


@equation
def velocity_command(
    ey: float, eth: float, u: float, v_ir: float, w_ir: float, k1: float, k2: float, k3: float
) -> tuple[float, float]:
    """``[υ_cmd, ω_cmd]`` of eq. 31 (m/s, rad/s).

    ``υ_cmd = υ_ir cos θ̃ + k1 u``, ``ω_cmd = ω_ir + k2 υ_ir ỹ + k3 υ_ir sin θ̃``, with
    ``u = V_s`` (bioinspired) or ``u = x̃`` (conventional backstepping).
    """
    return v_ir * cos(eth) + k1 * u, w_ir + k2 * v_ir * ey + k3 * v_ir * sin(eth)


@equation
def neuron_step(vs: float, x: float, A: float, B: float, D: float, dt: float) -> float:
    """The shunting neuron (eq. 32) advanced by ``dt`` (s) for a frozen input ``x``.

    ``V̇ = −A V + (B − V) f(x) − (D + V) g(x)``, ``f = max(x, 0)``, ``g = max(−x, 0)``
    (the paper's ``V_s1`` is a typo for ``V_si``). Linear in ``V`` for frozen ``x``, so it
    is integrated exactly: ``V`` stays in ``(−D, B)`` for any step and input.
    """
    f = max(x, 0.0)
    g = max(-x, 0.0)
    lam = A + f + g
    v_inf = (B * f - D * g) / lam
    return v_inf + (vs - v_inf) * exp(-lam * dt)


@equation
def neuron_rate(vs: float, x: float, A: float, B: float, D: float) -> float:
    """``V̇_s`` of eq. 32/33 at the state ``vs`` and input ``x``: ``−A V + (B − V) f(x) − (D + V) g(x)``."""
    return -A * vs + (B - vs) * max(x, 0.0) - (D + vs) * max(-x, 0.0)


# ------------------------------------------------- command derivative (design §6)
@equation
def filter_step(
    y: float, dy: float, u: float, f00: float, f01: float, f10: float, f11: float, g0: float, g1: float
) -> tuple[float, float]:
    """One exact-discretisation step of ``ÿ = ω_n² (u − y) − 2 ω_n ẏ`` (u held over the step).

    ``(f00 … f11)``, ``(g0, g1)`` are the transition matrix and input vector
    (:func:`filter_coefficients`). Returns the new ``(y, ẏ)``.
    """
    return f00 * y + f01 * dy + g0 * u, f10 * y + f11 * dy + g1 * u


@equation
def filter_derivative(
    y: float, dy: float, u: float, f00: float, f01: float, f10: float, f11: float, g0: float, g1: float, dt: float
) -> tuple[float, float, float]:
    """``torque.derivative = "filter"``: one :func:`filter_step` on ``u`` and the derivative estimate.

    The estimate is the filter output's change over the step, ``(y_f[k+1] − y_f[k])/dt`` (the
    mean of ``ẏ_f`` over the step), not ``ẏ_f`` at the sample instant: the latter's gain to a
    step of ``u`` vanishes as ``ω_n·dt`` grows, while this tends to the backward difference
    ``(u[k] − u[k−1])/dt`` as ``ω_n → ∞`` (``y_f`` then follows ``u`` within the step).
    Returns the new ``(y_f, ẏ_f, derivative)``.
    """
    yn, dyn = filter_step(y, dy, u, f00, f01, f10, f11, g0, g1)
    return yn, dyn, (yn - y) / dt


@equation
def backward_difference(u: float, u_prev: float, dt: float) -> float:
    """``torque.derivative = "difference"``: ``(u[k] − u[k−1])/dt``."""
    return (u - u_prev) / dt


@equation
def command_derivative(
    y: float,
    dy: float,
    u: float,
    first: bool,
    difference: bool,
    f00: float,
    f01: float,
    f10: float,
    f11: float,
    g0: float,
    g1: float,
    dt: float,
) -> tuple[float, float, float]:
    """The command derivative of ``torque.derivative`` = ``"filter"`` or, with ``difference``,
    ``"difference"`` (design §6) for the command ``u``: the state ``(y, dy)`` is the filter's output and
    rate (:func:`filter_derivative`) or, for the difference, the last command (:func:`backward_difference`;
    ``dy`` kept); ``first``: the first step, the state starts at ``(u, 0)`` (a zero derivative). Returns
    the new ``(y, dy)`` and the derivative.
    """
    y0 = y
    dy0 = dy
    if first:
        y0 = u
        dy0 = 0.0
    if difference:
        return u, dy0, backward_difference(u, y0, dt)
    yn, dyn, d = filter_derivative(y0, dy0, u, f00, f01, f10, f11, g0, g1, dt)
    return yn, dyn, d


@equation
def error_rate(
    ex: float, ey: float, v: float, w: float, v_ir: float, dpth: float, eth: float, dpx_b: float, dpy_b: float
) -> tuple[float, float, float]:
    """``(ẋ̃, ẏ̃, θ̃̇)`` of the body-frame error of eq. 28 (m/s, m/s, rad/s).

    ``(ex, ey)`` = ``(x̃, ỹ)``, ``θ̃`` = ``eth``; ``(v, w)`` the measured ``υ, ω``;
    ``(dpx_b, dpy_b)`` the estimator's position rate (eq. 12) rotated into the robot's body frame,
    ``dpth`` its heading rate. With ``ė = Ṗ_ir − [υ cos θ, υ sin θ]`` (world) and the rotation:
    ``ẋ̃ = ω ỹ + dpx_b − υ``, ``ẏ̃ = −ω x̃ + dpy_b``, ``θ̃̇ = θ̇_ir − ω``.
    (``v_ir`` is unused: kept for the reader; with an exact estimate ``dpx_b = υ_ir cos θ̃``.)
    """
    return w * ey + dpx_b - v, -w * ex + dpy_b, dpth - w


@equation
def command_rate(
    ey: float,
    eth: float,
    v_ir: float,
    dv_ir: float,
    dw_ir: float,
    dey: float,
    deth: float,
    du: float,
    k1: float,
    k2: float,
    k3: float,
) -> tuple[float, float]:
    """``torque.derivative = "analytic"``: ``(υ̇_cmd, ω̇_cmd)``, eq. 31 differentiated by the chain rule.

    ``υ̇_cmd = υ̇_ir cos θ̃ − υ_ir sin θ̃ θ̃̇ + k1 u̇``;
    ``ω̇_cmd = ω̇_ir + k2 (υ̇_ir ỹ + υ_ir ẏ̃) + k3 (υ̇_ir sin θ̃ + υ_ir cos θ̃ θ̃̇)``, with the
    estimator's rates ``υ̇_ir, ω̇_ir`` (eq. 13), the error rates (:func:`error_rate`) and ``u̇`` the
    neuron's rate (eq. 33, :func:`neuron_rate`) or ``ẋ̃`` (backstepping). No filter, no lag.
    """
    c = cos(eth)
    s = sin(eth)
    return (
        dv_ir * c - v_ir * s * deth + k1 * du,
        dw_ir + k2 * (dv_ir * ey + v_ir * dey) + k3 * (dv_ir * s + v_ir * c * deth),
    )


def filter_coefficients(wn: float, dt: float) -> tuple[float, float, float, float, float, float]:
    """``(f00, f01, f10, f11, g0, g1)`` of :func:`filter_step` for ``ω_n`` (rad/s) and ``dt`` (s)."""
    a = exp(-wn * dt)
    return (a * (1 + wn * dt), a * dt, -(wn**2) * dt * a, a * (1 - wn * dt), 1.0 - a * (1 + wn * dt), wn * wn * dt * a)


# ---------------------------------------------------------- torque law (eqs. 38–39)
@equation
def sliding_mode(
    v_cmd: float,
    w_cmd: float,
    dv_cmd: float,
    dw_cmd: float,
    v: float,
    w: float,
    a_hat: float,
    b_hat: float,
    ca: float,
    cb: float,
    phi: float,
) -> tuple[float, float]:
    """Unsaturated wheel torques ``(τ_L, τ_R)`` (N·m) of eqs. 38–39.

    ``U = ż_cmd + c ⊙ sgn(z_cmd − z)``; ``τ_L = U_a/(2â) − U_b/(2b̂)``,
    ``τ_R = U_a/(2â) + U_b/(2b̂)``: this pairs with ``τ_b = τ_R − τ_L`` (design §5, the
    paper's ``τ_L − τ_R`` turns the robot the wrong way).
    """
    half_a = (dv_cmd + ca * sat(v_cmd - v, phi)) / (2.0 * a_hat)
    half_b = (dw_cmd + cb * sat(w_cmd - w, phi)) / (2.0 * b_hat)
    return half_a - half_b, half_a + half_b


@equation
def saturate(tl: float, tr: float, lim: float, steer: bool) -> tuple[float, float]:
    """Wheel torques ``(τ_L, τ_R)`` limited to ``±lim`` (N·m) (design §5).

    ``steer = False`` clips each wheel alone. ``steer = True`` (steer priority) keeps
    ``τ_b = τ_R − τ_L`` (clipped to ``±2 lim``) and gives ``τ_a`` what remains,
    ``|τ_a| ≤ 2 lim − |τ_b|``; both keep each wheel within its limit.
    """
    if not steer:
        return clip(tl, -lim, lim), clip(tr, -lim, lim)
    tb = clip(tr - tl, -2.0 * lim, 2.0 * lim)
    room = 2.0 * lim - abs(tb)
    ta = clip(tl + tr, -room, room)
    return 0.5 * (ta - tb), 0.5 * (ta + tb)


# ----------------------------------------------------------------- learner (eq. 37)
@equation
def learner_terms(
    e_int: float, c_hat: float, d_hat: float, tau: float, z: float, k4: float, kd: float, h: float
) -> tuple[float, float, float, float, float, float, float]:
    """The terms of the backward-Euler closed form of eq. 37 that :func:`learner_step` and
    :func:`learner_drag_step` share, for the frozen torque ``tau`` and the velocity ``z`` measured at the
    step's end (``h`` the step, s): with the new estimate ``ẑ'`` still unknown, ``E' = R + h ẑ'``,
    ``S' = S0 + S1 ẑ'``, ``ĉ' = P − Q ẑ'`` (before its projection) and ``d̂' = Pd − Qd ẑ'``.
    Returns ``(R, S0, S1, P, Q, Pd, Qd)``.
    """
    R = e_int - h * z
    S0 = k4 * R - z
    S1 = 1.0 + h * k4
    hk4t = h * k4 * tau
    P = c_hat - hk4t * S0
    Q = hk4t * S1
    Pd = d_hat - h * kd * S0
    Qd = h * kd * S1
    return R, S0, S1, P, Q, Pd, Qd


@equation
def learner_step(
    z_hat: float,
    e_int: float,
    c_hat: float,
    d_hat: float,
    tau: float,
    z: float,
    k4: float,
    k5: float,
    kd: float,
    c_min: float,
    c_max: float,
    h: float,
) -> tuple[float, float, float, float]:
    """One backward-Euler step of eq. 37 for one channel (``υ`` with ``τ_a``, or ``ω`` with ``τ_b``).

    ``e = ẑ − z``, ``E = ∫e``, ``S = k4 E + e``; ``ẑ' = τ ĉ + d̂ − k4 e − k5 S``,
    ``E' = e``, ``ĉ' = −τ k4 S``, ``d̂' = −kd S`` (``kd = 0``: the paper). Linear in
    ``(ẑ, E, ĉ, d̂)`` for the frozen ``τ`` applied over the step and the velocity ``z``
    measured at its end, so solved in closed form (A-stable, design §5); ``ĉ`` is then
    projected onto ``[c_min, c_max]``. Returns the new ``(ẑ, E, ĉ, d̂)``.
    """
    R, S0, S1, P, Q, Pd, Qd = learner_terms(e_int, c_hat, d_hat, tau, z, k4, kd, h)
    den = 1.0 + h * k4 + h * k5 * S1 + h * tau * Q + h * Qd
    zn = (z_hat + h * (tau * P + Pd + k4 * z - k5 * S0)) / den
    return zn, R + h * zn, clip(P - Q * zn, c_min, c_max), Pd - Qd * zn


@equation
def learner_drag_step(
    z_hat: float,
    e_int: float,
    c_hat: float,
    d_hat: float,
    k_hat: float,
    tau: float,
    z: float,
    k4: float,
    k5: float,
    kd: float,
    kk: float,
    c_min: float,
    c_max: float,
    k_max: float,
    h: float,
) -> tuple[float, float, float, float, float]:
    """:func:`learner_step` with a learned viscous drag (opt-in ``learner.drag``, design §14, not in
    the paper): the model ``ẑ' = τ ĉ + d̂ − k̂ z − k4 e − k5 S`` and ``k̂' = kk z S`` (the regressor
    of ``k̂`` is ``−z`` as that of ``ĉ`` is ``τ``), so a wheel drag ``−k z`` (joint damping,
    back-EMF) is estimated beside ``ĉ`` instead of biasing it. Same backward-Euler closed form
    (``k̂`` is linear in ``ẑ`` for the frozen ``z``: ``k̂_new = k̂ + h kk z S_new``); ``ĉ`` is
    projected onto ``[c_min, c_max]``, ``k̂`` onto ``[0, k_max]`` (1/s). ``kk = 0`` holds ``k̂``;
    with ``k̂ = 0`` too it gives :func:`learner_step`'s values. Returns the new ``(ẑ, E, ĉ, d̂, k̂)``.
    """
    R, S0, S1, P, Q, Pd, Qd = learner_terms(e_int, c_hat, d_hat, tau, z, k4, kd, h)
    Pk = k_hat + h * kk * z * S0
    Qk = h * kk * z * S1
    den = 1.0 + h * k4 + h * k5 * S1 + h * tau * Q + h * Qd + h * z * Qk
    zn = (z_hat + h * (tau * P + Pd - Pk * z + k4 * z - k5 * S0)) / den
    return zn, R + h * zn, clip(P - Q * zn, c_min, c_max), Pd - Qd * zn, clip(Pk + Qk * zn, 0.0, k_max)


# ------------------------------------------------------------- ideal plant (eq. 34)
@equation
def harmonic(bias: float, amp: float, freq: float, phase: float, t: float) -> float:
    """Disturbance ``bias + amp cos(freq t + phase)`` at time ``t`` (s)."""
    return bias + amp * cos(freq * t + phase)


@equation
def unicycle_rk4(
    x: float,
    y: float,
    th: float,
    v: float,
    w: float,
    acc_v: float,
    acc_w: float,
    d0: float,
    d1: float,
    d2: float,
    d3: float,
    e0: float,
    e1: float,
    e2: float,
    e3: float,
    t: float,
    h: float,
) -> tuple[float, float, float, float, float]:
    """One RK4 step of length ``h`` (s) from ``t`` of the paper's plant for one robot.

    ``ẋ = υ cos θ``, ``ẏ = υ sin θ``, ``θ̇ = ω``, ``υ̇ = acc_v + d1(t)``, ``ω̇ = acc_w + d2(t)``
    with ``acc = diag(τ_a, τ_b) c`` held over the step and the harmonic disturbances
    ``d1 = harmonic(d0..d3)``, ``d2 = harmonic(e0..e3)``. The heading is not wrapped here.
    """
    hh = 0.5 * h
    a1 = acc_v + harmonic(d0, d1, d2, d3, t)
    b1 = acc_w + harmonic(e0, e1, e2, e3, t)
    am = acc_v + harmonic(d0, d1, d2, d3, t + hh)
    bm = acc_w + harmonic(e0, e1, e2, e3, t + hh)
    a4 = acc_v + harmonic(d0, d1, d2, d3, t + h)
    b4 = acc_w + harmonic(e0, e1, e2, e3, t + h)
    # stage 1
    kx1 = v * cos(th)
    ky1 = v * sin(th)
    kt1 = w
    # stage 2
    th2 = th + hh * kt1
    v2 = v + hh * a1
    kx2 = v2 * cos(th2)
    ky2 = v2 * sin(th2)
    kt2 = w + hh * b1
    # stage 3
    th3 = th + hh * kt2
    v3 = v + hh * am
    kx3 = v3 * cos(th3)
    ky3 = v3 * sin(th3)
    kt3 = w + hh * bm
    # stage 4
    th4 = th + h * kt3
    v4 = v + h * am
    kx4 = v4 * cos(th4)
    ky4 = v4 * sin(th4)
    kt4 = w + h * bm
    s = h / 6.0
    return (
        x + s * (kx1 + 2.0 * kx2 + 2.0 * kx3 + kx4),
        y + s * (ky1 + 2.0 * ky2 + 2.0 * ky3 + ky4),
        th + s * (kt1 + 2.0 * kt2 + 2.0 * kt3 + kt4),
        v + s * (a1 + 2.0 * am + 2.0 * am + a4),
        w + s * (b1 + 2.0 * bm + 2.0 * bm + b4),
    )


# ------------------------------------------------------- measurement of a rigid chassis
@equation
def planar_state(
    px: float,
    py: float,
    qw: float,
    qx: float,
    qy: float,
    qz: float,
    vx: float,
    vy: float,
    vz: float,
    wx: float,
    wy: float,
    wz: float,
    cx: float,
    cy: float,
    cz: float,
) -> tuple[float, float, float, float, float, float]:
    """Pose and body-frame velocity of a chassis point, from a free joint's state.

    ``(px, py)`` the body origin (m), ``(qw, qx, qy, qz)`` its orientation, ``(vx, vy, vz)``
    the origin's world-frame velocity (m/s), ``(wx, wy, wz)`` the body-frame angular
    velocity (rad/s) — MuJoCo's free-joint ``qpos``/``qvel`` — and ``(cx, cy, cz)`` the
    reference point (the axle midpoint) in the body frame (m).

    Returns ``(x, y, θ, υ, ω, up)``: the point's world position ``p + R c``; the heading
    ``θ = atan2(R10, R00)``; ``υ`` = the point's velocity ``v + ω_w × (R c)`` along the unit
    heading; ``ω`` = the world-z component of the angular velocity; ``up = R22`` the cosine
    of the chassis tilt (1 level, 0 on its side).
    """
    r00 = qw * qw + qx * qx - qy * qy - qz * qz
    r01 = 2.0 * (qx * qy - qw * qz)
    r02 = 2.0 * (qx * qz + qw * qy)
    r10 = 2.0 * (qw * qz + qx * qy)
    r11 = qw * qw - qx * qx + qy * qy - qz * qz
    r12 = 2.0 * (qy * qz - qw * qx)
    r20 = 2.0 * (qx * qz - qw * qy)
    r21 = 2.0 * (qy * qz + qw * qx)
    r22 = qw * qw - qx * qx - qy * qy + qz * qz
    # the reference point in world axes, relative to the origin
    ox = r00 * cx + r01 * cy + r02 * cz
    oy = r10 * cx + r11 * cy + r12 * cz
    # angular velocity in world axes
    gx = r00 * wx + r01 * wy + r02 * wz
    gy = r10 * wx + r11 * wy + r12 * wz
    gz = r20 * wx + r21 * wy + r22 * wz
    oz = r20 * cx + r21 * cy + r22 * cz
    ux = vx + gy * oz - gz * oy
    uy = vy + gz * ox - gx * oz
    n = hypot(r00, r10)
    return (px + ox, py + oy, atan2(r10 + 0.0, r00), (ux * r00 + uy * r10) / n, gz, r22)


# ------------------------------------------------------- wheel slip (the plant's outcome watch, design §8)
@equation
def slip_ratio(phidot: float, r: float, v: float, w: float, y: float, v_floor: float) -> float:
    """Slip ratio of one wheel: ``|r φ̇ − v_c| / max(|r φ̇|, |v_c|, v_floor)``, with ``φ̇`` the wheel's
    forward rate (rad/s), ``r`` its radius (m) and ``v_c = υ + y ω`` the forward speed its contact
    point would have if it rolled (``υ`` m/s, ``ω`` rad/s the chassis' body velocity at the axle
    midpoint; ``y = −l`` for the left wheel, ``+l`` for the right, ``l`` the half track, m). 0 when
    rolling, up to 2 when the wheel spins against the motion; below ``v_floor`` (m/s) the speeds are
    measured against that floor, so creeping at standstill is not slip."""
    rate = phidot * r
    vc = v + y * w
    return abs(rate - vc) / max(max(abs(rate), abs(vc)), v_floor)


# ------------------------------------------------------- sensors and odometry (design §8.3)
#: modulus of the counter hash (2^31 − 1): every product below stays under 2^53, exact in doubles
HASH_M = 2147483647.0


@equation
def hash_round(x: float, a: float, c: float) -> float:
    """One nonlinear round of the counter hash on ``x ∈ [0, 2^31−1)``: split into 16-bit ``lo`` and
    15-bit ``hi`` (exact: a power-of-two division), mix ``(a·lo + hi·lo + hi·hi + c)`` (< 2^34,
    exact), then a MINSTD multiply by 48271 (< 2^47, exact), both mod ``2^31 − 1``."""
    lo = x % 65536.0
    hi = (x - lo) / 65536.0
    y = (a * lo + hi * lo + hi * hi + c) % 2147483647.0
    return (48271.0 * y + x) % 2147483647.0


@equation
def hash_uniform(seed: float, i: float, k: float) -> float:
    """Counter-based uniform variate in (0, 1) of ``(seed, i, k)`` (non-negative integers as floats;
    ``seed`` taken mod 2^31 − 1, ``i`` < 2^20, ``k`` < 2^31): four :func:`hash_round` s of a
    combined key. Pure arithmetic on floats, exact in IEEE doubles, so every engine (compiled,
    step by step, a GPU port of this source) draws the same numbers for the same counter."""
    x = (seed % 2147483647.0 + 1.0) % 2147483647.0
    x = hash_round(x, 40692.0, i * 2053.0 + 12345.0)
    x = (x + k) % 2147483647.0
    x = hash_round(x, 39373.0, 7.0)
    x = hash_round(x, 48271.0, 11.0)
    x = hash_round(x, 16807.0, 13.0)
    return (x + 0.5) / 2147483647.0


@equation
def hash_normal(seed: float, i: float, k: float) -> float:
    """Zero-mean, unit-variance variate of the counter ``(seed, i, k)``: the sum of four
    :func:`hash_uniform` draws (counters ``4k … 4k+3``) centred and scaled by √3 (Irwin–Hall;
    bounded at ±2√3 ≈ ±3.46 σ; no ``log`` in the equation set, so no Box–Muller)."""
    k4 = 4.0 * k
    s = (
        hash_uniform(seed, i, k4)
        + hash_uniform(seed, i, k4 + 1.0)
        + hash_uniform(seed, i, k4 + 2.0)
        + hash_uniform(seed, i, k4 + 3.0)
    )
    return (s - 2.0) * 1.7320508075688772


@equation
def noisy_reading(x: float, sigma: float, seed: float, i: float, k: float) -> float:
    """A measurement of ``x`` with white Gaussian noise of standard deviation ``sigma`` (``x``'s units):
    ``x + sigma · hash_normal(seed, i, k)``; ``x`` itself, with no draw, for ``sigma = 0``. ``i`` names
    the measured quantity (and its stream), ``k`` the sample."""
    if sigma == 0.0:
        return x
    return x + sigma * hash_normal(seed, i, k)


@equation
def packet_received(p: float, seed: float, i: float, k: float) -> float:
    """Packet loss with probability ``p`` ∈ [0, 1): 1.0 when the packet of link ``i`` at control step
    ``k`` arrives, 0.0 when it is lost (``hash_uniform(seed, i, k) < p``)."""
    if hash_uniform(seed, i, k) >= p:
        return 1.0
    return 0.0


@equation
def encoder_angle(phi: float, cpr: float) -> float:
    """Wheel angle ``phi`` (rad) as an incremental encoder of ``cpr`` counts per revolution reports
    it: ``floor(phi·cpr/2π) · 2π/cpr`` (``x − x mod 1`` is ``floor``: Python's and numba's ``%``
    take the divisor's sign)."""
    c = phi * cpr / (2.0 * pi)
    return (c - c % 1.0) * (2.0 * pi) / cpr


@equation
def gyro_reading(wz: float, bias: float, sigma: float, seed: float, i: float, k: float) -> float:
    """Gyro z of robot ``i`` at sample ``k``: the true yaw rate ``wz`` (rad/s) plus a constant ``bias``
    and white noise of standard deviation ``sigma`` (rad/s, per sample; :func:`hash_normal`)."""
    return noisy_reading(wz + bias, sigma, seed, i, k)


@equation
def odometry_step(
    x: float, y: float, th: float, ql0: float, qr0: float, ql1: float, qr1: float, wz: float, r: float, ts: float
) -> tuple[float, float, float, float, float]:
    """Dead reckoning over one sensor period ``ts`` (s): the distance ``Δs = r (Δφ_L + Δφ_R)/2`` from
    the quantised forward wheel angles ``q·0 → q·1`` (rad; radius ``r`` m), the heading change
    ``Δθ = wz ts`` from the gyro (rad/s), the position advanced along the mid-period heading
    ``θ + Δθ/2``. Returns ``(x, y, θ wrapped, Δs, Δθ)``."""
    ds = 0.5 * r * ((ql1 - ql0) + (qr1 - qr0))
    dth = wz * ts
    hm = th + 0.5 * dth
    return x + ds * cos(hm), y + ds * sin(hm), wrap(th + dth), ds, dth
