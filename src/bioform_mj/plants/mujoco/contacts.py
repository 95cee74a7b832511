"""Contacts and distances between robots and with obstacles, watched inside the MuJoCo loop (design §19).

Two watches, compiled with numba and run by both engines:

* :func:`watch_contacts`, after **every physics step**: MuJoCo's own contact list (its broad and
  narrow phase already ran in ``mj_step``). Each contact whose geoms belong to two different
  robots, or to a robot and an obstacle, is one touch; its normal force comes from
  ``mj_contactForce``. Per follower and per kind of partner (robot, obstacle) it counts contact
  *events* (a touch more than :data:`EVENT_GAP_S` after the last one), the time touching, the peak
  normal force (N) and the largest *impulse* of one event (N·s: the normal force of every contact
  of the follower with that kind, summed, integrated over the event's physics steps).
* :func:`watch_proximity`, every :data:`PROXIMITY_DT` s (every control step when that is longer):
  the closest approach of each follower's collision geoms to any other robot's and to any
  obstacle's, by ``mj_geomDistance`` (MuJoCo's
  geometry, not centres), for the pairs a sort-and-sweep broad phase on the robots' bounding
  circles finds within :data:`EXACT_RANGE_M` (or the safety distance, if larger); pairs farther
  apart but within :data:`COARSE_RANGE_M` count with the gap of their bounding circles (a lower
  bound of the true distance; ``sep_exact`` says which). Below ``safety`` m a follower is too close.

The contact list is read in place: ``MjData.contact`` lies at the start of MuJoCo's arena (checked
when the watch is built, and after every chunk by :meth:`ContactReader.check`), ``ncon`` right after
``MjData.timer`` (checked against ``MjData.ncon``). ``mj_contactForce`` and ``mj_geomDistance`` are
called by symbol from compiled code (as ``mj_step`` is, :mod:`.mujoco_kernels`) and through ctypes
when numba's JIT is off.
"""

from __future__ import annotations

import ctypes
import importlib.util
import math
import os
from typing import NamedTuple

import numpy as np

from bioform_mj.core.equations import HAVE_NUMBA, njit

#: below this gap of two robots' bounding circles (m), their geoms' distance is computed exactly
EXACT_RANGE_M = 0.25
#: a touch within this long (s) of the last one continues its contact event (a robot pushing on an
#: obstacle makes and breaks contact every few physics steps: one event, not hundreds)
EVENT_GAP_S = 0.05
#: the distances are evaluated every this many seconds of simulated time (every control step when
#: that is longer): a robot at 1 m/s moves 4 mm between two looks; contacts are read every physics step
PROXIMITY_DT = 0.004
#: up to this gap (m) of bounding circles, a pair counts with that gap (a lower bound); the same as
#: the exact range: a wider one costs a sweep over many more pairs (+4 % of mj_step at n = 256 for 2 m)
COARSE_RANGE_M = 0.25


# ---------------------------------------------------------------- the two C functions, both ways
def _libmujoco_path() -> str | None:
    """Path of the libmujoco shipped with the ``mujoco`` Python package (without importing it)."""
    spec = importlib.util.find_spec("mujoco")
    if spec is None or not spec.submodule_search_locations:
        return None
    d = list(spec.submodule_search_locations)[0]
    names = sorted(
        f
        for f in os.listdir(d)
        if f.startswith("libmujoco.so") or (f.startswith("libmujoco.") and f.endswith(".dylib"))
    )
    return os.path.join(d, names[-1]) if names else None


def _ctypes_lib():
    path = _libmujoco_path()
    lib = ctypes.CDLL(path)
    lib.mj_geomDistance.restype = ctypes.c_double
    lib.mj_geomDistance.argtypes = [ctypes.c_void_p] * 2 + [ctypes.c_int] * 2 + [ctypes.c_double, ctypes.c_void_p]
    lib.mj_contactForce.restype = None
    lib.mj_contactForce.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p]
    return lib


_LIB = None


def geom_distance(mp, dp, g1, g2, distmax):
    """``mj_geomDistance(m, d, g1, g2, distmax, NULL)``: signed distance of two geoms (m), capped at ``distmax``."""
    global _LIB
    if _LIB is None:
        _LIB = _ctypes_lib()
    return _LIB.mj_geomDistance(mp, dp, int(g1), int(g2), float(distmax), None)


def contact_force(mp, dp, c, f6):
    """``mj_contactForce(m, d, c, f6)``: contact ``c``'s force and torque in its frame (``f6[0]``: normal, N)."""
    global _LIB
    if _LIB is None:
        _LIB = _ctypes_lib()
    _LIB.mj_contactForce(mp, dp, int(c), f6.ctypes.data)


if HAVE_NUMBA:
    import numba
    from numba import types
    from numba.extending import overload

    _gd = types.ExternalFunction(
        "mj_geomDistance", types.float64(types.intp, types.intp, types.int32, types.int32, types.float64, types.intp)
    )
    _cf = types.ExternalFunction("mj_contactForce", types.void(types.intp, types.intp, types.int32, types.intp))

    @overload(geom_distance)
    def _geom_distance_nb(mp, dp, g1, g2, distmax):
        def impl(mp, dp, g1, g2, distmax):
            return _gd(mp, dp, numba.int32(g1), numba.int32(g2), distmax, 0)

        return impl

    @overload(contact_force)
    def _contact_force_nb(mp, dp, c, f6):
        def impl(mp, dp, c, f6):
            _cf(mp, dp, numba.int32(c), f6.ctypes.data)

        return impl


class ContactList(NamedTuple):
    """What :func:`watch_contacts` reads and writes (``n`` followers; arrays updated in place).

    ``ncon`` (1,) int32 view of ``MjData.ncon``; ``con`` int32 view of the contact buffer;
    ``meta`` (4,) int64: int32 words per contact, offsets of ``geom1``/``geom2`` in them, contacts the
    view holds; ``owner`` (ngeom,): the follower (0-based) owning each geom, −1 for none (floor,
    markers), −2 − k for obstacle k. Per follower × [robots, obstacles]: ``ci`` (n, 2, 6) int64
    ``[touching at the last step (0/1), events, steps touching, partner at the first touch,
    hit (scratch), partner (scratch)]``; ``cf`` (n, 2, 6) float64 ``[first touch s (−1: never),
    impulse of the event under way N·s, largest impulse N·s, peak force N, force (scratch), last
    touch s]``;
    ``f6`` (6,) scratch; ``hdt`` s the physics step. Few fields on purpose: a kernel's arguments are
    passed by value, each array as a struct."""

    ncon: np.ndarray
    con: np.ndarray
    meta: np.ndarray
    owner: np.ndarray
    ci: np.ndarray
    cf: np.ndarray
    f6: np.ndarray
    hdt: float


#: column indices of ContactList.ci / .cf and Proximity.rf / .ri
TOUCHING, EVENTS, STEPS, PARTNER, HIT, WHO = range(6)
FIRST_T, IMP, MAX_IMP, PEAK_F, FSUM, LAST_T = range(6)
MIN_SEP, MIN_SEP_T, MIN_CLEAR, CLOSE_T, NOW = range(5)
SEP_EXACT, SEP_WITH, CLEAR_EXACT, CLEAR_WITH, CLOSE_STEPS = range(5)


class Proximity(NamedTuple):
    """What :func:`watch_proximity` reads and writes (``n`` followers, ``m`` obstacles).

    ``gstart`` (n + 1,), ``glist``: each follower's collision geoms (CSR); ``ogeom`` (m,) obstacle
    geoms; ``obst`` (m, 3) their ``[x, y, bounding radius]`` m; ``rad`` (n,) each robot's bounding
    radius about its axle midpoint, m; ``ranges`` (4,) ``[exact range m, coarse range m, safety
    distance m, control steps between two looks]``; results ``rf`` (n, 5) float64 ``[min
    separation m, its time s, min obstacle clearance m, first time too close s, distance this step
    (scratch)]`` and ``ri`` (n, 5) int64
    ``[separation exact (0/1), nearest robot, clearance exact, nearest obstacle, steps too close]``;
    scratch ``box`` (n + m, 4) ``[lo, x, y, r]`` and ``order`` (n + m,)."""

    gstart: np.ndarray
    glist: np.ndarray
    ogeom: np.ndarray
    obst: np.ndarray
    rad: np.ndarray
    ranges: np.ndarray
    rf: np.ndarray
    ri: np.ndarray
    box: np.ndarray
    order: np.ndarray


@njit
def watch_contacts(mp, dp, ncon, con, meta, owner, ci, cf, f6, hdt, t):
    """After one physics step ending at ``t`` s: the robot–robot and robot–obstacle contacts of
    MuJoCo's contact list, per follower (see the module docstring). The arguments after ``dp`` are
    the fields of a :class:`ContactList`, passed one by one (``*cl``): unpacking a named tuple in a
    kernel called every physics step costs its arrays' reference counts, ~0.25 µs a call."""
    stride, o1, o2, cap = meta[0], meta[1], meta[2], meta[3]
    n = ci.shape[0]
    nc = min(int(ncon[0]), cap)
    found = False
    for c in range(nc):
        a = owner[con[c * stride + o1]]
        b = owner[con[c * stride + o2]]
        if a == -1 or b == -1 or a == b or (a < 0 and b < 0):  # floor, markers, a robot's own geoms
            continue
        if a >= 0 and b >= 0:
            kind, r, q, other = 0, a, b, a
        elif a >= 0:
            kind, r, q, other = 1, a, -2 - b, -1
        else:
            kind, r, q, other = 1, b, -2 - a, -1
        if not found:  # the first touch of this step: clear the scratch
            found = True
            for i in range(n):
                for k in range(2):
                    ci[i, k, HIT] = 0
                    ci[i, k, WHO] = -1
                    cf[i, k, FSUM] = 0.0
        contact_force(mp, dp, c, f6)
        f = abs(f6[0])
        ci[r, kind, HIT] = 1
        cf[r, kind, FSUM] += f
        if ci[r, kind, WHO] < 0:
            ci[r, kind, WHO] = q
        if other >= 0:  # the other robot touches this one
            ci[q, 0, HIT] = 1
            cf[q, 0, FSUM] += f
            if ci[q, 0, WHO] < 0:
                ci[q, 0, WHO] = r
    if not found:
        for i in range(n):
            ci[i, 0, TOUCHING] = 0
            ci[i, 1, TOUCHING] = 0
        return
    for i in range(n):
        for k in range(2):
            if ci[i, k, HIT]:
                if cf[i, k, LAST_T] < 0 or t - cf[i, k, LAST_T] > EVENT_GAP_S:
                    ci[i, k, EVENTS] += 1
                    cf[i, k, IMP] = 0.0
                    if cf[i, k, FIRST_T] < 0:
                        cf[i, k, FIRST_T] = t
                        ci[i, k, PARTNER] = ci[i, k, WHO]
                ci[i, k, STEPS] += 1
                cf[i, k, IMP] += cf[i, k, FSUM] * hdt
                cf[i, k, MAX_IMP] = max(cf[i, k, MAX_IMP], cf[i, k, IMP])
                cf[i, k, PEAK_F] = max(cf[i, k, PEAK_F], cf[i, k, FSUM])
                ci[i, k, TOUCHING] = 1
                cf[i, k, LAST_T] = t
            else:
                ci[i, k, TOUCHING] = 0


@njit
def _pair_distance(mp, dp, gstart, glist, ogeom, rng, a, b, n, gap):
    """Distance (m) of items ``a`` (a follower), ``b`` (a follower < n, else obstacle b − n): the
    least ``mj_geomDistance`` of their geoms if ``gap`` (of bounding circles) is within ``rng``,
    else ``gap``; and whether it is exact."""
    if gap > rng:
        return gap, False
    best = rng
    for ga in range(gstart[a], gstart[a + 1]):
        g1 = glist[ga]
        if b < n:
            for gb in range(gstart[b], gstart[b + 1]):
                d = geom_distance(mp, dp, g1, glist[gb], rng)
                if d < best:
                    best = d
        else:
            d = geom_distance(mp, dp, g1, ogeom[b - n], rng)
            if d < best:
                best = d
    return best, True


@njit
def _note(rf, ri, p, q, d, exact, t, robot):
    if d < rf[p, NOW]:
        rf[p, NOW] = d
    col, when, ex, with_ = (
        (MIN_SEP, MIN_SEP_T, SEP_EXACT, SEP_WITH) if robot else (MIN_CLEAR, -1, CLEAR_EXACT, CLEAR_WITH)
    )
    if d < rf[p, col]:
        rf[p, col] = d
        if when >= 0:
            rf[p, when] = t
        ri[p, ex] = 1 if exact else 0
        ri[p, with_] = q


@njit
def watch_proximity(mp, dp, gstart, glist, ogeom, obst, rad, ranges, rf, ri, box, order, pose, t):
    """After a control step at ``t`` s with the robots at ``pose`` (n, 3) (axle midpoints): each
    follower's closest approach to other robots and to obstacles, and the time too close (see the
    module docstring). The arguments between ``dp`` and ``pose`` are the fields of a
    :class:`Proximity` (``*px``). Sort and sweep on x over the bounding circles (insertion sort of
    the last order: nearly sorted from one step to the next): O(n + m + pairs) per step."""
    exact_range, reach, safety = ranges[0], ranges[1], ranges[2]
    n = pose.shape[0]
    m = obst.shape[0]
    N = n + m
    for i in range(n):
        box[i, 1] = pose[i, 0]
        box[i, 2] = pose[i, 1]
        box[i, 3] = rad[i]
        rf[i, NOW] = np.inf
    for k in range(m):
        box[n + k, 1] = obst[k, 0]
        box[n + k, 2] = obst[k, 1]
        box[n + k, 3] = obst[k, 2]
    for a in range(N):
        box[a, 0] = box[a, 1] - box[a, 3]
    for ia in range(1, N):  # insertion sort of order by lo
        v = order[ia]
        j = ia - 1
        while j >= 0 and box[order[j], 0] > box[v, 0]:
            order[j + 1] = order[j]
            j -= 1
        order[j + 1] = v
    for ia in range(N):
        a = order[ia]
        ra = box[a, 3]
        hi = box[a, 1] + ra + reach
        for ib in range(ia + 1, N):
            b = order[ib]
            if box[b, 0] > hi:
                break
            if a >= n and b >= n:
                continue
            rr = ra + box[b, 3]
            dy = box[a, 2] - box[b, 2]
            if abs(dy) > rr + reach:
                continue
            dx = box[a, 1] - box[b, 1]
            gap = math.sqrt(dx * dx + dy * dy) - rr
            if gap > reach:
                continue
            r, o = (a, b) if a < n else (b, a)  # r: a follower
            d, exact = _pair_distance(mp, dp, gstart, glist, ogeom, exact_range, r, o, n, gap)
            if o < n:
                _note(rf, ri, r, o, d, exact, t, True)
                _note(rf, ri, o, r, d, exact, t, True)
            else:
                _note(rf, ri, r, o - n, d, exact, t, False)
    if safety > 0:
        for i in range(n):
            if rf[i, NOW] < safety:
                if ri[i, CLOSE_STEPS] == 0:
                    rf[i, CLOSE_T] = t
                ri[i, CLOSE_STEPS] += 1


class Watched(NamedTuple):
    """Per follower, in plain names: what the watches recorded (views, for the summary)."""

    events: np.ndarray  # (n, 2) contact events with [robots, obstacles]
    touch_steps: np.ndarray  # (n, 2) physics steps touching
    first_t: np.ndarray  # (n, 2) s, −1: never
    partner: np.ndarray  # (n, 2) at the first touch: follower / obstacle index
    max_imp: np.ndarray  # (n, 2) N·s
    peak_f: np.ndarray  # (n, 2) N
    hdt: float  # s, physics step
    min_sep: np.ndarray  # (n,) m, inf: no robot within the coarse range
    sep_exact: np.ndarray  # (n,) bool
    min_sep_t: np.ndarray  # (n,) s
    min_sep_with: np.ndarray  # (n,) follower index
    min_clear: np.ndarray  # (n,) m
    min_clear_with: np.ndarray  # (n,) obstacle index
    close_steps: np.ndarray  # (n,) control steps below the safety distance
    close_t: np.ndarray  # (n,) s, the first of them
    safety: float  # m
    exact_range: float  # m
    every: int  # control steps between two looks at the distances
    off: str  # why MuJoCo's contact list is not read ("": it is)


class ContactReader:
    """Builds the watches' arrays for a compiled scene and checks its view of the contact list."""

    def __init__(
        self,
        model,
        data,
        owner: np.ndarray,
        geoms: list[list[int]],
        obstacle_geoms: list[int],
        radii: np.ndarray,
        safety: float,
        control_dt: float,
        zadr: np.ndarray | None = None,
    ) -> None:
        import mujoco

        m, d = model, data
        self.model, self.data = m, d
        mujoco.mj_forward(m, d)
        self.off = ""  # why the contact list is not read (empty: it is)
        if d.ncon == 0 and zadr is not None and len(zadr):
            # the bindings' contact views carry the address only with a contact: sink the robots into
            # the floor for one forward pass (the arena does not move), then put them back
            q = d.qpos.copy()
            d.qpos[zadr] -= 1.0
            mujoco.mj_forward(m, d)
            self._layout(m, d)
            d.qpos[:] = q
            mujoco.mj_forward(m, d)
        elif d.ncon:
            self._layout(m, d)
        else:
            self.off = "no contact to learn MuJoCo's contact layout from"
        self._build(m, d, owner, geoms, obstacle_geoms, radii, safety, control_dt)

    def _layout(self, m, d) -> None:
        """Where the contact list and ``ncon`` lie, from the bindings' views (a contact must exist)."""
        if d.ncon == 0:
            self.off = "no contact to learn MuJoCo's contact layout from (no collision geom touches the floor)"
            return
        c = d.contact
        base = c.dist.__array_interface__["data"][0]
        stride = c.dist.strides[0]
        if stride % 4 or (c.geom1.__array_interface__["data"][0] - base) % 4:
            raise RuntimeError("unexpected mjContact layout")
        self.base = base
        cap = int(d.narena // stride)  # the contacts start the arena (checked below and per chunk)
        self.con = np.ctypeslib.as_array((ctypes.c_int32 * (cap * stride // 4)).from_address(base))
        td = d.timer.duration
        ncon_addr = td.__array_interface__["data"][0] + len(td) * td.strides[0]
        self.ncon = np.ctypeslib.as_array((ctypes.c_int32 * 1).from_address(ncon_addr))
        o1 = (c.geom1.__array_interface__["data"][0] - base) // 4
        o2 = (c.geom2.__array_interface__["data"][0] - base) // 4
        w = stride // 4
        if (
            int(self.ncon[0]) != d.ncon
            or not np.array_equal([self.con[k * w + o1] for k in range(d.ncon)], c.geom1)
            or not np.array_equal([self.con[k * w + o2] for k in range(d.ncon)], c.geom2)
        ):
            raise RuntimeError("cannot read MuJoCo's contact list in place (layout differs from MuJoCo 3/4's)")
        self.meta = np.array([w, o1, o2, cap], dtype=np.int64)

    def _build(self, m, d, owner, geoms, obstacle_geoms, radii, safety, control_dt) -> None:
        if self.off:  # nothing read: an empty view (cap 0); ncon still from after the timers
            td = d.timer.duration
            ncon_addr = td.__array_interface__["data"][0] + len(td) * td.strides[0]
            self.ncon = np.ctypeslib.as_array((ctypes.c_int32 * 1).from_address(ncon_addr))
            self.con = np.zeros(1, dtype=np.int32)
            self.meta = np.array([1, 0, 0, 0], dtype=np.int64)
            self.base = None
        n = len(geoms)
        mo = len(obstacle_geoms)
        gstart = np.zeros(n + 1, dtype=np.int64)
        gstart[1:] = np.cumsum([len(g) for g in geoms])
        glist = np.array([g for row in geoms for g in row], dtype=np.int64)
        og = np.array(obstacle_geoms, dtype=np.int64)
        obst = np.array([[d.geom_xpos[g, 0], d.geom_xpos[g, 1], _horizontal_radius(m, g)] for g in og]).reshape(mo, 3)
        self.contacts = ContactList(
            self.ncon,
            self.con,
            self.meta,
            np.ascontiguousarray(owner, dtype=np.int64),
            np.zeros((n, 2, 6), dtype=np.int64),
            np.zeros((n, 2, 6)),
            np.zeros(6),
            float(m.opt.timestep),
        )
        exact = float(max(EXACT_RANGE_M, safety))
        self.every = max(1, int(round(PROXIMITY_DT / control_dt)))  # control steps between two looks
        self.proximity = Proximity(
            gstart,
            glist,
            og,
            obst,
            np.ascontiguousarray(radii, dtype=float),
            np.array([exact, float(max(COARSE_RANGE_M, exact)), float(safety), float(self.every)]),
            np.zeros((n, 5)),
            np.zeros((n, 5), dtype=np.int64),
            np.zeros((n + mo, 4)),
            np.arange(n + mo, dtype=np.int64),
        )
        self.reset()

    def reset(self) -> None:
        """Forget everything watched (a new run from the initial state)."""
        ci, cf = self.contacts.ci, self.contacts.cf
        ci[:] = 0
        ci[:, :, PARTNER] = -1
        cf[:] = 0.0
        cf[:, :, FIRST_T] = -1.0
        cf[:, :, LAST_T] = -1.0
        rf, ri = self.proximity.rf, self.proximity.ri
        rf[:] = -1.0
        rf[:, MIN_SEP] = np.inf
        rf[:, MIN_CLEAR] = np.inf
        ri[:] = 0
        ri[:, SEP_WITH] = -1
        ri[:, CLEAR_WITH] = -1

    def watched(self) -> Watched:
        """What was watched, per follower, in plain names (views)."""
        ci, cf = self.contacts.ci, self.contacts.cf
        rf, ri = self.proximity.rf, self.proximity.ri
        return Watched(
            ci[:, :, EVENTS],
            ci[:, :, STEPS],
            cf[:, :, FIRST_T],
            ci[:, :, PARTNER],
            cf[:, :, MAX_IMP],
            cf[:, :, PEAK_F],
            self.contacts.hdt,
            rf[:, MIN_SEP],
            ri[:, SEP_EXACT].astype(bool),
            rf[:, MIN_SEP_T],
            ri[:, SEP_WITH],
            rf[:, MIN_CLEAR],
            ri[:, CLEAR_WITH],
            ri[:, CLOSE_STEPS],
            rf[:, CLOSE_T],
            float(self.proximity.ranges[2]),
            float(self.proximity.ranges[0]),
            self.every,
            self.off,
        )

    def check(self) -> None:
        """Raise if MuJoCo moved its contact list away from where the watch reads it."""
        d = self.data
        if int(self.ncon[0]) != d.ncon:
            raise RuntimeError("the contact watch lost MjData.ncon")
        if self.base is not None and d.ncon and d.contact.dist.__array_interface__["data"][0] != self.base:
            raise RuntimeError("MuJoCo moved its contact list; the contact watch cannot follow it")


def _horizontal_radius(m, g: int) -> float:
    """Horizontal bounding radius (m) of geom ``g`` about its own centre."""
    import mujoco

    t = int(m.geom_type[g])
    s = m.geom_size[g]
    if t == int(mujoco.mjtGeom.mjGEOM_BOX):
        return float(math.hypot(s[0], s[1]))
    if t in (int(mujoco.mjtGeom.mjGEOM_CYLINDER), int(mujoco.mjtGeom.mjGEOM_SPHERE)):
        return float(s[0])
    return float(m.geom_rbound[g])


def robot_geoms(model, data, base_ids: np.ndarray, axle_world: np.ndarray) -> tuple[list[list[int]], np.ndarray]:
    """Per follower the collision geoms (``contype`` or ``conaffinity`` set) of its bodies (the
    subtree of its base), and its horizontal bounding radius about its axle midpoint ``axle_world``
    (n, 2) (m): the farthest reach of a geom's bounding sphere (``geom_rbound``) from that point."""
    m, d = model, data
    root = m.body_rootid
    # the collision geoms of each tree, in geom order, in one pass (a pass over every geom per robot was n²)
    collide = np.flatnonzero((m.geom_contype != 0) | (m.geom_conaffinity != 0))
    by_root: dict[int, list[int]] = {}
    for g, r in zip(collide.tolist(), root[m.geom_bodyid[collide]].tolist()):
        by_root.setdefault(r, []).append(g)
    geoms: list[list[int]] = []
    radii = np.zeros(len(base_ids))
    for i, b in enumerate(base_ids):
        gs = list(by_root.get(int(root[b]), ()))
        geoms.append(gs)
        for g in gs:
            r = math.hypot(*(d.geom_xpos[g, :2] - axle_world[i])) + float(m.geom_rbound[g])
            radii[i] = max(radii[i], r)
    return geoms, radii
