"""Programs compiled in the background (identify/compile_ahead.py) compute what the jitted
function computes, at the caller's precision, and step aside where they do not fit."""

import jax
import jax.numpy as jnp
import numpy as np

from activebonds.identify.compile_ahead import ahead


def _f(x, pair):
    a, b = pair
    return jnp.sin(x) @ a + jnp.sum(b**2), x * 1e-20


def _args(n=5):
    x = jnp.asarray(np.linspace(0.1, 1.0, n))
    return x, (jnp.asarray(np.arange(n * 3.0).reshape(n, 3)), jnp.asarray(np.ones(2)))


def test_the_program_compiled_ahead_equals_the_jitted_one_in_64_bits():
    with jax.enable_x64(True):
        jitted = jax.jit(_f)
        args = _args()
        run = ahead(jitted, *args)
        got, want = run(*args), jitted(*args)
        assert run._compiled is not None  # the background's program ran
        assert got[0].dtype == jnp.float64 and got[1].dtype == jnp.float64
        np.testing.assert_array_equal(got[0], want[0])
        # 1e-20 x survives in float64 only: the background traced at the caller's precision
        assert float(got[1][0]) > 0.0
        np.testing.assert_array_equal(got[1], want[1])


def test_other_shapes_and_tracers_go_to_the_jitted_function():
    with jax.enable_x64(True):
        jitted = jax.jit(_f)
        run = ahead(jitted, *_args(5))
        other = _args(4)
        np.testing.assert_allclose(run(*other)[0], jitted(*other)[0], rtol=0, atol=0)
        x, pair = _args(5)
        grad = jax.jacfwd(lambda y: run(y, pair)[0])(x)  # traced: not the compiled program
        expected = (jnp.cos(x)[:, None] * pair[0]).T  # [3, n]
        np.testing.assert_allclose(grad, expected, rtol=1e-12)


def test_shape_structures_compile_ahead_of_any_data():
    with jax.enable_x64(True):
        jitted = jax.jit(_f)
        x, (a, b) = _args()
        structs = [jax.ShapeDtypeStruct(v.shape, v.dtype) for v in (x, a, b)]
        run = ahead(jitted, structs[0], (structs[1], structs[2]))
        np.testing.assert_array_equal(run(x, (a, b))[0], jitted(x, (a, b))[0])
        assert run._compiled is not None
