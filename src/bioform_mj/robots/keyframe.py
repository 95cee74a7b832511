"""Start a robot in one of its file's keyframes (design §13.2): the robot that runs is the maker's pose.

A published MJCF often carries keyframes (MuJoCo Menagerie's robots: ``home``); the pose at ``qpos0``
may be one no one runs (Hello Robot Stretch: the wrist folded into the base). The mapping's
``keyframe = "NAME"`` (default ``""``: ``home`` where the file has one; ``"none"``: ``qpos0``)
selects one; :func:`apply_keyframe` makes its configuration the robot's rest configuration in the
spec, before anything is read from it:

- the configuration: the keyframe's ``qpos`` of the hinge and slide joints other than the root and
  the driven wheels (the root pose stays the scenario's). A keyframe that gives ``ctrl`` only (the
  servos' targets) is settled first: the robot alone, its base pinned, runs under gravity with that
  ``ctrl`` until its joints rest (at most :data:`SETTLE_MAX_S`), and the settled configuration is the
  keyframe's;
- baked into the bodies: each moved body's frame becomes its frame at that configuration and the
  joint's ``ref`` its value there, so ``qpos0`` is the keyframe while the joint coordinates (ranges,
  servo targets, ``springref``, fixed tendon lengths) mean what they meant. Several joints on one
  body: a joint's anchor and axis are carried through the joints after it (exact). Equalities
  written relative to ``qpos0`` (joint and tendon couplings) get their polynomial shifted, so each
  relation is the one the file states (springs rest at ``springref``, which baking leaves alone);
- the robot's own position servos (fixed gain, affine bias ``b1 < 0``) hold the keyframe: their
  target (the keyframe's ``ctrl``; without one, the ``ctrl`` at which the servo pushes nothing there)
  is moved into the bias (``b0 += g·target``, ``ctrlrange −= target``), so the scene's ``ctrl = 0``
  holds it.

Frozen and locked joints (design §13) are then held at the keyframe, because it is ``qpos0``.
"""

from __future__ import annotations

from math import comb
from pathlib import Path

import mujoco
import numpy as np

from bioform_mj.robots.layout import ModelError, _quoted, _spec_actuator, _spec_body, _spec_joint
from bioform_mj.robots.refs import RobotRef

__all__ = ["apply_keyframe", "keyframe_name", "SETTLE_MAX_S", "KeyframeResult"]

#: the longest a ctrl-only keyframe is settled, s of simulated time
SETTLE_MAX_S = 5.0
#: joint speed (rad/s or m/s) below which a settling robot is at rest
REST_SPEED = 1e-4

#: settled configurations of ctrl-only keyframes, by file (path, mtime), keyframe and what is driven
_SETTLED: dict[tuple, tuple[np.ndarray, float, float]] = {}

_HINGE, _SLIDE = int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)
_J = mujoco.mjtObj.mjOBJ_JOINT


class KeyframeResult(tuple):
    """``(spec, model, name, qpos, notes)``: the spec with the keyframe baked in, its compiled model,
    the keyframe's name (``""``: none), the configuration ``((joint, value), …)`` and the notes."""


def keyframe_name(model: mujoco.MjModel, path: Path, ref: RobotRef) -> str:
    """The keyframe ``ref`` selects in ``model`` (``""``: none). Raises :class:`ModelError` naming the
    keyframes the file has for an unknown name."""
    names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_KEY, k) or "" for k in range(model.nkey)]
    if not ref.keyframe:
        return "home" if "home" in names else ""
    if ref.keyframe.lower() == "none":
        return ""
    if ref.keyframe not in names:
        have = f"the file has {_quoted(n for n in names if n)}" if any(names) else "the file has no named keyframe"
        raise ModelError(f"{path}: no keyframe '{ref.keyframe}' (mapping keyframe; {have}; \"none\": qpos0)")
    return ref.keyframe


def _rot(axis: np.ndarray, angle: float) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_axisAngle2Quat(q, axis, angle)
    m = np.zeros(9)
    mujoco.mju_quat2Mat(m, q)
    return m.reshape(3, 3)


def _joint_motion(model: mujoco.MjModel, j: int, d: float) -> tuple[np.ndarray, np.ndarray]:
    """``(R, t)``: the rigid motion ``x → R x + t`` of joint ``j`` displaced by ``d`` from ``qpos0``,
    in its body's frame (a hinge turns about its axis through its anchor, a slide moves along it)."""
    axis = np.asarray(model.jnt_axis[j], float)
    if int(model.jnt_type[j]) == _SLIDE:
        return np.eye(3), axis * d
    p = np.asarray(model.jnt_pos[j], float)
    R = _rot(axis, d)
    return R, p - R @ p


def _settle(
    spec: mujoco.MjSpec, model: mujoco.MjModel, key: int, root: int, moved: list[int], driven: set[int]
) -> tuple[np.ndarray, float, float]:
    """The configuration the robot alone settles at under keyframe ``key``'s ``ctrl``, its root welded
    where the file puts it (a copy of ``spec`` without the root's free joint), the joints of ``moved``
    not in ``driven`` held at ``qpos0`` by a joint equality (the scene holds them there): ``(qpos,
    seconds, residual speed)``, ``qpos`` in ``model``'s layout (the root's entries as in ``qpos0``)."""
    pinned = spec.copy()
    for k in list(pinned.keys):
        pinned.delete(k)
    dt = float(model.opt.timestep)
    for j in moved:  # what the scene holds without a servo (frozen, locked) stays at qpos0 meanwhile
        if j not in driven:
            sj = _spec_joint(pinned, model, j)
            sj.name = sj.name or f"bioform_keyframe_hold_{j}"
            pinned.add_equality(
                type=mujoco.mjtEq.mjEQ_JOINT, objtype=mujoco.mjtObj.mjOBJ_JOINT, name1=sj.name, solref=[2 * dt, 1.0]
            )
    if root >= 0:
        pinned.delete(_spec_joint(pinned, model, root))
    m = pinned.compile()
    shift = lambda j: j - (1 if 0 <= root < j else 0)  # noqa: E731  (joint ids after the removed root)
    data = mujoco.MjData(m)
    for j in range(model.njnt):
        if j != root:
            n = 4 if model.jnt_type[j] == int(mujoco.mjtJoint.mjJNT_BALL) else 1
            n = 7 if model.jnt_type[j] == int(mujoco.mjtJoint.mjJNT_FREE) else n
            a, a2 = int(model.jnt_qposadr[j]), int(m.jnt_qposadr[shift(j)])
            data.qpos[a2 : a2 + n] = model.key_qpos[key, a : a + n]
    data.ctrl[:] = model.key_ctrl[key]
    dofs = np.array([int(m.jnt_dofadr[shift(j)]) for j in moved], int)
    steps, speed = 0, np.inf
    while steps * dt < SETTLE_MAX_S:
        mujoco.mj_step(m, data)
        steps += 1
        speed = float(np.max(np.abs(data.qvel[dofs]))) if dofs.size else 0.0
        if steps * dt >= 0.2 and speed < REST_SPEED:
            break
    qpos = np.array(model.qpos0, float)
    for j in range(model.njnt):
        if j != root:
            n = 4 if model.jnt_type[j] == int(mujoco.mjtJoint.mjJNT_BALL) else 1
            n = 7 if model.jnt_type[j] == int(mujoco.mjtJoint.mjJNT_FREE) else n
            a, a2 = int(model.jnt_qposadr[j]), int(m.jnt_qposadr[shift(j)])
            qpos[a : a + n] = data.qpos[a2 : a2 + n]
    return qpos, steps * dt, speed


def _servos(model: mujoco.MjModel, wheels: set[int]) -> list[int]:
    """The robot's position servos (fixed gain > 0, affine bias with ``b1 < 0``) not on a wheel joint."""
    joint_trn = (int(mujoco.mjtTrn.mjTRN_JOINT), int(mujoco.mjtTrn.mjTRN_JOINTINPARENT))
    return [
        a
        for a in range(model.nu)
        if model.actuator_gaintype[a] == int(mujoco.mjtGain.mjGAIN_FIXED)
        and model.actuator_biastype[a] == int(mujoco.mjtBias.mjBIAS_AFFINE)
        and model.actuator_gainprm[a, 0] > 0
        and model.actuator_biasprm[a, 1] < 0
        and not (model.actuator_trntype[a] in joint_trn and int(model.actuator_trnid[a, 0]) in wheels)
    ]


def _driven(model: mujoco.MjModel, servos: list[int]) -> set[int]:
    """Joints the position servos ``servos`` move: on a joint, every joint of a fixed tendon, and
    (repeatedly) every joint a joint equality couples to one of them."""
    out: set[int] = set()
    for a in servos:
        trn, obj = int(model.actuator_trntype[a]), int(model.actuator_trnid[a, 0])
        if trn == int(mujoco.mjtTrn.mjTRN_TENDON):
            adr, num = int(model.tendon_adr[obj]), int(model.tendon_num[obj])
            out |= {
                int(model.wrap_objid[w])
                for w in range(adr, adr + num)
                if model.wrap_type[w] == int(mujoco.mjtWrap.mjWRAP_JOINT)
            }
        elif trn in (int(mujoco.mjtTrn.mjTRN_JOINT), int(mujoco.mjtTrn.mjTRN_JOINTINPARENT)):
            out.add(obj)
    pairs = [
        (int(model.eq_obj1id[e]), int(model.eq_obj2id[e]))
        for e in range(model.neq)
        if model.eq_type[e] == int(mujoco.mjtEq.mjEQ_JOINT) and model.eq_obj2id[e] >= 0
    ]
    grown = True
    while grown:
        grown = False
        for j1, j2 in pairs:
            if (j1 in out) != (j2 in out):
                out |= {j1, j2}
                grown = True
    return out


def _shift_poly(coef: np.ndarray, dx: float, dy: float) -> np.ndarray:
    """Coefficients (5) of ``g(u) = f(u + dx) − dy`` for the polynomial ``f`` of ``coef`` (degree ≤ 4):
    a relation ``y − y0 = f(x − x0)`` rewritten about ``x0 + dx, y0 + dy``."""
    g = np.zeros(5)
    for k, c in enumerate(coef[:5]):
        for i in range(k + 1):
            g[i] += c * comb(k, i) * dx ** (k - i)
    g[0] -= dy
    return g


def apply_keyframe(spec: mujoco.MjSpec, model: mujoco.MjModel, path: Path, ref: RobotRef) -> KeyframeResult:
    """Bake the keyframe ``ref`` selects into ``spec`` (see the module docstring); returns a
    :class:`KeyframeResult`. Without a keyframe (none selected, none named ``home``) ``spec`` and
    ``model`` come back untouched."""
    name = keyframe_name(model, path, ref)
    if not name:
        opted = (
            ref.keyframe.lower() == "none"
            and model.nkey
            and mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, "home") >= 0
        )
        notes = ("keyframe 'home' not used (mapping keyframe = none): the robot starts at qpos0",) if opted else ()
        return KeyframeResult((spec, model, "", (), notes))
    key = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, name)
    skey = spec.keys[key]
    has_qpos, has_ctrl = len(skey.qpos) > 0, len(skey.ctrl) > 0
    base = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, ref.base or "base")
    root = -1
    if (
        base >= 0
        and model.body_jntnum[base]
        and model.jnt_type[model.body_jntadr[base]] == int(mujoco.mjtJoint.mjJNT_FREE)
    ):
        root = int(model.body_jntadr[base])
    wheels = {
        mujoco.mj_name2id(model, _J, n) for n in (ref.left_wheel or "left_wheel", ref.right_wheel or "right_wheel")
    } - {-1}
    moved = [j for j in range(model.njnt) if int(model.jnt_type[j]) in (_HINGE, _SLIDE) and j not in wheels]
    notes: list[str] = []
    if has_qpos:
        qpos = np.array(model.key_qpos[key], float)
        how = "its qpos"
    else:
        driven = moved if ref.free_joints else _driven(model, _servos(model, wheels))
        where = Path(path).resolve()
        memo = (str(where), where.stat().st_mtime_ns, name, root, tuple(moved), tuple(sorted(driven)))
        if memo not in _SETTLED:  # a team of one robot kind settles it once (0.24 s for Stretch)
            _SETTLED[memo] = _settle(spec, model, key, root, moved, set(driven))
        qpos, t, speed = _SETTLED[memo]
        qpos = qpos.copy()
        for j in set(moved) - set(driven):  # held by the scene, not by a servo: exactly where the file puts it
            qpos[model.jnt_qposadr[j]] = model.qpos0[model.jnt_qposadr[j]]
        how = f"ctrl only: the servos' targets, settled with the base pinned in {t:.2g} s" + (
            f" (still moving {speed:.2g}/s at {SETTLE_MAX_S:g} s)" if speed >= REST_SPEED else ""
        )
    other = [
        j
        for j in range(model.njnt)
        if j != root
        and int(model.jnt_type[j]) not in (_HINGE, _SLIDE)
        and not np.allclose(
            qpos[model.jnt_qposadr[j] : model.jnt_qposadr[j] + (4 if model.jnt_type[j] != 0 else 7)],
            model.qpos0[model.jnt_qposadr[j] : model.jnt_qposadr[j] + (4 if model.jnt_type[j] != 0 else 7)],
        )
    ]
    disp = {j: float(qpos[model.jnt_qposadr[j]] - model.qpos0[model.jnt_qposadr[j]]) for j in moved}
    disp = {j: d for j, d in disp.items() if abs(d) > 1e-12}

    # the servos' hold targets (in the file's coordinates), from the original model
    servos = _servos(model, wheels)
    if has_ctrl:
        target = {a: float(model.key_ctrl[key, a]) for a in servos}
    else:
        data = mujoco.MjData(model)
        data.qpos[:] = qpos
        mujoco.mj_forward(model, data)
        target = {
            a: float(-(model.actuator_biasprm[a, 0] + model.actuator_biasprm[a, 1] * data.actuator_length[a]))
            / float(model.actuator_gainprm[a, 0])
            for a in servos
        }
    ignored = [
        a
        for a in range(model.nu)
        if has_ctrl and a not in target and abs(model.key_ctrl[key, a]) > 0 and not _on(model, a, wheels)
    ]

    # bake: body frames and joint refs, by body (joints in their order; design §13.2)
    sjoints = {j: _spec_joint(spec, model, j) for j in disp}
    sacts = {a: _spec_actuator(spec, model, a) for a in target}
    for b in sorted({int(model.jnt_bodyid[j]) for j in disp}):
        js = list(range(int(model.body_jntadr[b]), int(model.body_jntadr[b] + model.body_jntnum[b])))
        motion = {j: _joint_motion(model, j, disp.get(j, 0.0)) for j in js}
        R_tot, t_tot = np.eye(3), np.zeros(3)
        for j in js:  # frame' = frame ∘ A1 ∘ … ∘ An, Ai joint i's motion to the keyframe
            R, t = motion[j]
            R_tot, t_tot = R_tot @ R, R_tot @ t + t_tot
        S_R, S_t = np.eye(3), np.zeros(3)  # S_i = A_{i+1} ∘ … ∘ A_n: joint i moves by S_i⁻¹ M_i S_i
        for j in reversed(js):
            if not np.allclose(S_R, np.eye(3), atol=0, rtol=0) or np.any(S_t):
                sj = sjoints.get(j) or _spec_joint(spec, model, j)
                sj.pos = S_R.T @ (np.asarray(model.jnt_pos[j], float) - S_t)
                sj.axis = S_R.T @ np.asarray(model.jnt_axis[j], float)
            R, t = motion[j]
            S_R, S_t = R @ S_R, R @ S_t + t
        sb = _spec_body(spec, model, b)
        if sb.frame is not None:
            raise ModelError(f"{path}: keyframe '{name}': body '{sb.name}' sits in a <frame> (not supported)")
        R_old = np.zeros(9)
        mujoco.mju_quat2Mat(R_old, np.asarray(model.body_quat[b], float))
        R_old = R_old.reshape(3, 3)
        q_new = np.zeros(4)
        mujoco.mju_mat2Quat(q_new, (R_old @ R_tot).reshape(-1))
        sb.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT
        sb.pos = np.asarray(model.body_pos[b], float) + R_old @ t_tot
        sb.quat = q_new
    deg = bool(spec.compiler.degree)
    for j, sj in sjoints.items():
        v = float(qpos[model.jnt_qposadr[j]])
        sj.ref = np.degrees(v) if deg and int(model.jnt_type[j]) == _HINGE else v
    # equalities relative to qpos0 (joint couplings): each relation kept as the file states it
    for e in range(model.neq):
        if int(model.eq_type[e]) != int(mujoco.mjtEq.mjEQ_JOINT):
            continue
        j1, j2 = int(model.eq_obj1id[e]), int(model.eq_obj2id[e])
        dy, dx = disp.get(j1, 0.0), disp.get(j2, 0.0) if j2 >= 0 else 0.0
        if dy or dx:
            data = np.array(spec.equalities[e].data, float)
            data[:5] = _shift_poly(np.asarray(model.eq_data[e, :5], float), dx, dy)
            spec.equalities[e].data = data
    for a, c in target.items():
        sa = sacts[a]
        lo, hi = (float(x) for x in model.actuator_ctrlrange[a])
        if model.actuator_ctrllimited[a]:
            if not lo <= c <= hi:
                notes.append(
                    f"keyframe '{name}': target {c:.4g} of actuator {_act(model, a)} clipped to [{lo:g}, {hi:g}]"
                )
                c = min(max(c, lo), hi)
            sa.ctrlrange = [lo - c, hi - c]
            sa.ctrllimited = 1
        bp = np.array(sa.biasprm, float)
        bp[0] = float(model.actuator_biasprm[a, 0]) + float(model.actuator_gainprm[a, 0]) * c
        sa.biasprm = bp
        target[a] = c
    # tendon couplings are relative to length0 (at qpos0): each kept as the file states it. A tendon
    # spring's default rest length is taken at qpos_spring (springref), which baking leaves alone
    L0_old = np.array(model.tendon_length0, float)
    try:
        new = spec.compile()
    except Exception as exc:  # a baked pose that no longer compiles is the keyframe's fault: say so
        raise ModelError(f"{path}: keyframe '{name}' does not compile once applied: {exc}") from exc
    dL = np.array(new.tendon_length0, float) - L0_old
    changed = False
    for e in range(model.neq):
        if int(model.eq_type[e]) == int(mujoco.mjtEq.mjEQ_TENDON):
            t1, t2 = int(model.eq_obj1id[e]), int(model.eq_obj2id[e])
            dy, dx = dL[t1], dL[t2] if t2 >= 0 else 0.0
            if dy or dx:
                data = np.array(spec.equalities[e].data, float)
                data[:5] = _shift_poly(np.asarray(model.eq_data[e, :5], float), dx, dy)
                spec.equalities[e].data = data
                changed = True
    if changed:
        new = spec.compile()

    config = tuple((_jname(model, j), float(qpos[model.jnt_qposadr[j]])) for j in disp)
    why = (
        'the file has one named home: used by default; mapping keyframe = "none" for qpos0'
        if not ref.keyframe
        else "mapping keyframe"
    )
    holds = [f"{_act(model, a)} -> {c:.4g}" for a, c in target.items() if abs(c) > 0]
    notes.insert(
        0,
        f"keyframe '{name}' ({why}; {how}): the robot starts and is held there"
        + (": " + ", ".join(f"{n} = {v:.4g}" for n, v in config) if config else " (every joint at qpos0)")
        + ("; position actuator(s) hold " + ", ".join(holds) if holds else ""),
    )
    if ignored:
        notes.append(
            f"keyframe '{name}': ctrl of actuator(s) {_quoted(_act(model, a) for a in ignored)} ignored (not position "
            "servos: the scene keeps them at ctrl = 0)"
        )
    if other:
        notes.append(
            f"keyframe '{name}': ball/free joint(s) {_quoted(_jname(model, j) for j in other)} left at qpos0 "
            "(only hinge and slide joints are baked)"
        )
    return KeyframeResult((spec, new, name, config, tuple(notes)))


def _on(model: mujoco.MjModel, a: int, wheels: set[int]) -> bool:
    joint_trn = (int(mujoco.mjtTrn.mjTRN_JOINT), int(mujoco.mjtTrn.mjTRN_JOINTINPARENT))
    return int(model.actuator_trntype[a]) in joint_trn and int(model.actuator_trnid[a, 0]) in wheels


def _jname(model: mujoco.MjModel, j: int) -> str:
    return mujoco.mj_id2name(model, _J, j) or f"joint#{j}"


def _act(model: mujoco.MjModel, a: int) -> str:
    return mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a) or f"actuator#{a}"
