"""The batch engine's equations are the CPU engine's, from the same source: numba and Warp
versions of every scalar equation agree on random inputs (float64: to rounding; float32:
within float32 tolerance)."""
import math

import numpy as np
import pytest

wp = pytest.importorskip("warp")
pytest.importorskip("numba")

from bioform_mj.batch import standin_equations as E  # noqa: E402
from bioform_mj.batch.samesource import numba_equations, warp_equations, warp_map  # noqa: E402

wp.config.quiet = True
N = 400


def _u(lo, hi):
    return lambda rng: rng.uniform(lo, hi, N)


def _choice(*vals):
    return lambda rng: rng.choice(np.array(vals, dtype=float), N)


# name: (input generators, number of outputs, angle outputs (compared modulo 2π))
SPECS = {
    "wrap": ([_u(-30, 30)], 1, (0,)),
    "sat": ([_u(-3, 3), _choice(0.0, 0.1, 1.0)], 1, ()),
    "clip": ([_u(-3, 3), _u(-2, -0.5), _u(0.5, 2)], 1, ()),
    "tracking_error": ([_u(-5, 5), _u(-5, 5), _u(-9, 9), _u(-5, 5), _u(-5, 5), _u(-4, 4)], 3, (2,)),
    "velocity_command": ([_u(-2, 2), _u(-2, 2), _u(-3.1, 3.1), _u(-2, 2), _u(-1, 3), _u(-1, 1),
                          _u(0, 5), _u(0, 50), _u(0, 10)], 2, ()),
    "neuron_step": ([_u(-1, 2), _u(-3, 3), _u(0.5, 20), _u(0.1, 5), _u(0.1, 5), _choice(1e-3, 1e-2, 0.1)], 1, ()),
    "wheel_torques": ([_u(-50, 50), _u(-50, 50), _u(0.1, 1), _u(2, 20), _u(1, 20), _choice(0.0, 1.0)], 3, ()),
    "learner_channel": ([_u(-2, 2), _u(-1, 1), _u(0.1, 10), _u(-1, 1), _u(-20, 20), _u(-2, 2),
                         _u(1, 500), _u(0, 5), _u(0, 1), _choice(1e-3, 5e-3), _u(0.01, 0.1), _u(10, 20)], 4, ()),
    "body_state": ([_u(-1, 1), _u(-0.2, 0.2), _u(-0.2, 0.2), _u(-1, 1), _u(-2, 2), _u(-2, 2),
                    _u(-3, 3), _u(-3, 3), _u(-3, 3)], 3, (0,)),
}


def _unit_quat(args):
    """Normalise the first four inputs of body_state into a unit quaternion."""
    q = np.stack(args[:4])
    q /= np.linalg.norm(q, axis=0)
    return [*q, *args[4:]]


@pytest.fixture(scope="module")
def nb():
    return numba_equations(E)


def test_every_equation_has_a_spec():
    from bioform_mj.batch.samesource import equation_functions

    assert set(equation_functions(E)) == set(SPECS)


def _inputs(name, seed):
    gens, nout, angles = SPECS[name]
    rng = np.random.default_rng(seed)
    args = [g(rng) for g in gens]
    if name == "body_state":
        args = _unit_quat(args)
    # both compilers see the same float32-representable inputs
    return [np.asarray(a, dtype=np.float32).astype(np.float64) for a in args], nout, angles


def _reference(nb, name, args, nout):
    f = getattr(nb, name)
    out = np.array([f(*[float(a[i]) for a in args]) for i in range(N)], dtype=float)
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
    got = warp_map(getattr(warp_equations(E, wp.float64), name), len(args), nout, wp.float64)(*args)
    np.testing.assert_array_less(_diff(got, ref, angles), 1e-12 * (1.0 + np.abs(ref)))


@pytest.mark.parametrize("name", sorted(SPECS))
def test_warp_float32_matches_numba(nb, name):
    args, nout, angles = _inputs(name, 2)
    ref = _reference(nb, name, args, nout)
    got = warp_map(getattr(warp_equations(E, wp.float32), name), len(args), nout, wp.float32)(*args)
    # float32: a few ulps of the largest intermediate; the inputs span |x| <= 50
    tol = 2e-5 * (1.0 + np.abs(ref)) if name != "learner_channel" else 2e-4 * (1.0 + np.abs(ref))
    np.testing.assert_array_less(_diff(got, ref, angles), tol)


def test_wrap_is_floored_modulo_in_warp():
    """Warp's float ``%`` is C fmod: without the rewrite, wrap(4.0) would be 4.0."""
    a = np.array([4.0, -4.0, math.pi, -math.pi, 3 * math.pi, 100.0])
    got = warp_map(warp_equations(E, wp.float64).wrap, 1, 1, wp.float64)(a)[:, 0]
    np.testing.assert_allclose(got, [E.wrap(x) for x in a], atol=1e-12)
    assert np.all(got <= math.pi) and np.all(got > -math.pi)


def test_sign_branch_and_bool_output(nb):
    f = warp_map(warp_equations(E, wp.float32).sat, 2, 1)
    np.testing.assert_array_equal(f([2.0, -2.0, 0.0], [0.0, 0.0, 0.0])[:, 0], [1.0, -1.0, 0.0])
    g = warp_map(warp_equations(E, wp.float32).wheel_torques, 6, 3)
    out = g([100.0, 0.0], [0.0, 0.0], [0.5, 0.5], [10.0, 10.0], [5.0, 5.0], [1.0, 1.0])
    assert out[0, 2] == 1.0 and out[1, 2] == 0.0
