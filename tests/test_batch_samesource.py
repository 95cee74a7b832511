"""The batch engine's equations are the CPU engine's, from the same source: numba and Warp
versions of every scalar equation agree on random inputs (float64: to rounding; float32:
within float32 tolerance)."""

import math

import numpy as np
import pytest

wp = pytest.importorskip("warp")
pytest.importorskip("numba")

from bioform_mj.batch.samesource import warp_equations, warp_map  # noqa: E402
from bioform_mj.core import equations as E  # noqa: E402

wp.config.quiet = True
N = 400


def _u(lo, hi):
    return lambda rng: rng.uniform(lo, hi, N)


def _choice(*vals):
    return lambda rng: rng.choice(np.array(vals, dtype=float), N)


def _int(lo, hi):
    """Integers in [lo, hi) as floats (the counter hash's inputs; hi ≤ 2^30 stays an integer in float32)."""
    return lambda rng: rng.integers(lo, hi, N).astype(float)


# name: (input generators, number of outputs, angle outputs (compared modulo 2π))
_phi = _choice(0.0, 0.1)
SPECS = {
    "wrap": ([_u(-30, 30)], 1, (0,)),
    "sat": ([_u(-3, 3), _choice(0.0, 0.1, 1.0)], 1, ()),
    "clip": ([_u(-3, 3), _u(-2, -0.5), _u(0.5, 2)], 1, ()),
    "estimator_euler": ([*(_u(-5, 5) for _ in range(10)), _choice(1e-3, 1e-2)], 5, (2,)),
    "tracking_error": (
        [_u(-5, 5), _u(-5, 5), _u(-9, 9), _u(-5, 5), _u(-5, 5), _u(-4, 4), _u(-5, 5), _u(-5, 5)],
        3,
        (2,),
    ),
    "velocity_command": (
        [_u(-2, 2), _u(-3.1, 3.1), _u(-2, 2), _u(-1, 3), _u(-1, 1), _u(0, 5), _u(0, 50), _u(0, 10)],
        2,
        (),
    ),
    "neuron_step": ([_u(-1, 2), _u(-3, 3), _u(0.5, 20), _u(0.1, 5), _u(0.1, 5), _choice(1e-3, 1e-2, 0.1)], 1, ()),
    "filter_step": (
        [_u(-2, 2), _u(-20, 20), _u(-2, 2), _u(0.5, 1), _u(0, 1e-3), _u(-3, 0), _u(0.5, 1), _u(0, 0.1), _u(0, 3)],
        2,
        (),
    ),
    "filter_derivative": (
        [
            _u(-2, 2),
            _u(-20, 20),
            _u(-2, 2),
            _u(0.5, 1),
            _u(0, 1e-3),
            _u(-3, 0),
            _u(0.5, 1),
            _u(0, 0.1),
            _u(0, 3),
            _choice(1e-3, 1e-2),
        ],
        3,
        (),
    ),
    "backward_difference": ([_u(-2, 2), _u(-2, 2), _choice(1e-3, 1e-2)], 1, ()),
    "estimator_rates": (
        [
            _u(-3, 3),
            _u(-2, 2),
            _u(-2, 2),
            _u(-1, 1),
            _u(-1, 1),
            _u(-1, 1),
            _u(-1, 1),
            _u(-1, 1),
            _u(0, 20),
            _u(0, 20),
            _u(0, 20),
            _u(0, 30),
            _u(0, 30),
            _u(0, 2),
            _u(0, 2),
            _phi,
            _phi,
        ],
        5,
        (),
    ),
    "neuron_rate": ([_u(-1, 2), _u(-3, 3), _u(0.5, 20), _u(0.1, 5), _u(0.1, 5)], 1, ()),
    "error_rate": (
        [_u(-2, 2), _u(-2, 2), _u(-2, 2), _u(-3, 3), _u(-2, 2), _u(-3, 3), _u(-3.1, 3.1), _u(-2, 2), _u(-2, 2)],
        3,
        (),
    ),
    "command_rate": (
        [
            _u(-2, 2),
            _u(-3.1, 3.1),
            _u(-1, 3),
            _u(-5, 5),
            _u(-5, 5),
            _u(-2, 2),
            _u(-3, 3),
            _u(-5, 5),
            _u(0, 5),
            _u(0, 50),
            _u(0, 10),
        ],
        2,
        (),
    ),
    "sliding_mode": (
        [
            _u(-2, 2),
            _u(-2, 2),
            _u(-5, 5),
            _u(-5, 5),
            _u(-2, 2),
            _u(-2, 2),
            _u(0.1, 1),
            _u(2, 20),
            _u(0, 5),
            _u(0, 5),
            _phi,
        ],
        2,
        (),
    ),
    "saturate": ([_u(-50, 50), _u(-50, 50), _u(1, 20), _choice(0.0, 1.0)], 2, ()),
    "learner_terms": (
        [_u(-1, 1), _u(0.1, 10), _u(-1, 1), _u(-20, 20), _u(-2, 2), _u(1, 500), _u(0, 1), _choice(1e-3, 5e-3)],
        7,
        (),
    ),
    "learner_step": (
        [
            _u(-2, 2),
            _u(-1, 1),
            _u(0.1, 10),
            _u(-1, 1),
            _u(-20, 20),
            _u(-2, 2),
            _u(1, 500),
            _u(0, 50),
            _u(0, 1),
            _u(0.01, 0.1),
            _u(10, 20),
            _choice(1e-3, 5e-3),
        ],
        4,
        (),
    ),
    "learner_drag_step": (
        [
            _u(-2, 2),
            _u(-1, 1),
            _u(0.1, 10),
            _u(-1, 1),
            _u(0, 5),
            _u(-20, 20),
            _u(-2, 2),
            _u(1, 500),
            _u(0, 50),
            _u(0, 1),
            _u(0, 50),
            _u(0.01, 0.1),
            _u(10, 20),
            _u(1, 10),
            _choice(1e-3, 5e-3),
        ],
        5,
        (),
    ),
    "harmonic": ([_u(-1, 1), _u(-1, 1), _u(0, 3), _u(-3, 3), _u(0, 20)], 1, ()),
    "unicycle_rk4": (
        [
            _u(-5, 5),
            _u(-5, 5),
            _u(-3, 3),
            _u(-2, 2),
            _u(-2, 2),
            _u(-5, 5),
            _u(-5, 5),
            *[_u(-1, 1)] * 8,
            _u(0, 20),
            _choice(1e-3, 1e-2),
        ],
        5,
        (),
    ),
    "planar_state": (
        [
            _u(-5, 5),
            _u(-5, 5),
            _u(-1, 1),
            _u(-0.2, 0.2),
            _u(-0.2, 0.2),
            _u(-1, 1),
            *[_u(-2, 2)] * 3,
            *[_u(-3, 3)] * 3,
            *[_u(-0.2, 0.2)] * 3,
        ],
        6,
        (2,),
    ),
    "slot_reference": (
        [_u(-5, 5), _u(-5, 5), _u(-3, 3), _u(-2, 2), _u(-2, 2), _u(-1, 1), _u(-1, 1)],
        5,
        (2,),
    ),
    "slot_error": (
        [_u(-5, 5), _u(-5, 5), _u(-3, 3), _u(-2, 2), _u(-2, 2), _u(-1, 1), _u(-1, 1)]
        + [_u(-5, 5), _u(-5, 5), _u(-4, 4), _choice(0.0, 1.0)],
        5,
        (2,),
    ),
    "command_derivative": (
        [_u(-2, 2), _u(-20, 20), _u(-2, 2), _choice(0.0, 1.0), _choice(0.0, 1.0)]
        + [_u(0.5, 1), _u(0, 1e-3), _u(-3, 0), _u(0.5, 1), _u(0, 0.1), _u(0, 3), _choice(1e-3, 1e-2)],
        3,
        (),
    ),
    "formation_offset": ([_u(-1, 1), _u(-1, 1), _u(-4, 4), _choice(0.0, 1.0)], 2, ()),
    "slip_ratio": ([_u(-20, 20), _u(0.02, 0.1), _u(-1, 1), _u(-3, 3), _u(-0.2, 0.2), _choice(0.05)], 1, ()),
    "hash_round": ([_int(0, 2**30), _choice(40692.0, 39373.0, 48271.0, 16807.0), _int(0, 2**30)], 1, ()),
    "hash_uniform": ([_int(0, 2**30), _int(0, 2**20), _int(0, 2**30)], 1, ()),
    "hash_normal": ([_int(0, 2**30), _int(0, 2**20), _int(0, 2**28)], 1, ()),
    "noisy_reading": ([_u(-5, 5), _choice(0.0, 0.01, 0.3), _int(0, 2**30), _int(0, 2**20), _int(0, 2**28)], 1, ()),
    "packet_received": ([_choice(0.0, 0.2, 0.5, 0.99), _int(0, 2**30), _int(0, 2**20), _int(0, 2**30)], 1, ()),
    "encoder_angle": ([_u(-100, 100), _choice(64.0, 360.0, 4096.0)], 1, ()),
    "gyro_reading": (
        [_u(-3, 3), _u(-0.1, 0.1), _choice(0.0, 0.01), _int(0, 2**20), _int(0, 64), _int(0, 2**20)],
        1,
        (),
    ),
    "odometry_step": (
        [_u(-5, 5), _u(-5, 5), _u(-3, 3), _u(-50, 50), _u(-50, 50), _u(-50, 50), _u(-50, 50), _u(-3, 3)]
        + [_u(0.02, 0.1), _choice(1e-3, 1e-2)],
        5,
        (2,),
    ),
}
#: arguments that are ``bool`` in the source (passed as ``x != 0``)
BOOL_ARGS = {"saturate": (3,), "formation_offset": (3,), "slot_error": (10,), "command_derivative": (3, 4)}
#: exact integer arithmetic beyond float32's 24-bit mantissa (the counter hash), or a floor that
#: float32 rounding moves by a whole encoder count: meaningful in float64 only (the precision the
#: batch engine's controller state uses)
FLOAT64_ONLY = {
    "hash_round",
    "hash_uniform",
    "hash_normal",
    "gyro_reading",
    "encoder_angle",
    "noisy_reading",
    "packet_received",
}


def _unit_quat(args, at):
    """Normalise the inputs ``at … at+3`` into a unit quaternion."""
    q = np.stack(args[at : at + 4])
    q /= np.linalg.norm(q, axis=0)
    return [*args[:at], *q, *args[at + 4 :]]


@pytest.fixture(scope="module")
def nb():
    return E  # the CPU engine's own numba-compiled equations


def test_every_equation_has_a_spec():
    from bioform_mj.batch.samesource import equation_functions

    assert set(equation_functions(E)) == set(SPECS) == set(E.EQUATIONS)


def _inputs(name, seed):
    gens, nout, angles = SPECS[name]
    rng = np.random.default_rng(seed)
    args = [g(rng) for g in gens]
    if name == "planar_state":
        args = _unit_quat(args, 2)
    # both compilers see the same float32-representable inputs
    return [np.asarray(a, dtype=np.float32).astype(np.float64) for a in args], nout, angles


def _reference(nb, name, args, nout):
    f = getattr(nb, name)
    bools = BOOL_ARGS.get(name, ())
    out = np.array(
        [f(*[bool(a[i]) if k in bools else float(a[i]) for k, a in enumerate(args)]) for i in range(N)], dtype=float
    )
    return out.reshape(N, nout)


def _diff(a, b, angles):
    d = np.abs(a - b)
    for c in angles:
        d[:, c] = np.abs(np.pi - np.mod(np.pi - (a[:, c] - b[:, c]), 2 * np.pi))
    return d


@pytest.mark.parametrize("name", sorted(SPECS))
def test_warp_float64_matches_numba(nb, name):
    args, nout, angles = _inputs(name, 1)
    ref = _reference(nb, name, args, nout)
    got = warp_map(
        getattr(warp_equations(E, wp.float64), name), len(args), nout, wp.float64, bool_args=BOOL_ARGS.get(name, ())
    )(*args)
    np.testing.assert_array_less(_diff(got, ref, angles), 1e-12 * (1.0 + np.abs(ref)))


@pytest.mark.parametrize("name", sorted(SPECS))
def test_warp_float32_matches_numba(nb, name):
    if name in FLOAT64_ONLY:
        pytest.skip("exact only in float64 (integer hash / floor)")
    args, nout, angles = _inputs(name, 2)
    ref = _reference(nb, name, args, nout)
    got = warp_map(
        getattr(warp_equations(E, wp.float32), name), len(args), nout, wp.float32, bool_args=BOOL_ARGS.get(name, ())
    )(*args)
    # float32: a few ulps of the largest intermediate; the inputs span |x| <= 50
    tol = (
        2e-5 * (1.0 + np.abs(ref)) if name not in ("learner_step", "learner_drag_step") else 2e-4 * (1.0 + np.abs(ref))
    )
    np.testing.assert_array_less(_diff(got, ref, angles), tol)


def test_wrap_is_floored_modulo_in_warp():
    """Warp's float ``%`` is C fmod: without the rewrite, wrap(4.0) would be 4.0."""
    a = np.array([4.0, -4.0, math.pi, -math.pi, 3 * math.pi, 100.0])
    got = warp_map(warp_equations(E, wp.float64).wrap, 1, 1, wp.float64)(a)[:, 0]
    np.testing.assert_allclose(got, [E.wrap(x) for x in a], atol=1e-12)
    assert np.all(got <= math.pi) and np.all(got > -math.pi)


def test_sign_branch_and_bool_argument():
    f = warp_map(warp_equations(E, wp.float32).sat, 2, 1)
    np.testing.assert_array_equal(f([2.0, -2.0, 0.0], [0.0, 0.0, 0.0])[:, 0], [1.0, -1.0, 0.0])
    g = warp_map(warp_equations(E, wp.float32).saturate, 4, 2, bool_args=(3,))
    out = g([30.0, 30.0], [10.0, 10.0], [20.0, 20.0], [1.0, 0.0])
    np.testing.assert_allclose(out[0], [20.0, 0.0])  # steer priority keeps τ_b = −20
    np.testing.assert_allclose(out[1], [20.0, 10.0])  # per wheel
