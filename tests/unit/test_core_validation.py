"""The core validates what it is given: tiles, kalman and grid, and their state classes, fed
NaN, inf, huge, empty, wrongly shaped and wrongly typed arguments, on numpy's path and on the
compiled one.

The rule every case checks (``obeys``): the call raises a ValueError whose message names
the spoiled argument (in the "name:" it starts with), or it returns a result that is finite
everywhere and right (each test says how it knows: an explicit loop, the textbook formula,
an invariant); never another exception, never a NaN or inf in a result. A refused call
leaves the caller's arrays, and a state object everything it holds, as they were.

Hypothesis draws which argument to spoil and how from a fixed seed (``derandomize``), so
every run checks the same cases.
"""

import dataclasses
import enum
import math
import re
import sys
import tracemalloc
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimation_nodes.core import errors
from estimation_nodes.core.grid import likelihood_field, occupancy
from estimation_nodes.core.grid import steps as grid
from estimation_nodes.core.grid.localization import GridLocalization
from estimation_nodes.core.grid.model import _compiled_kernels
from estimation_nodes.core.grid.motion import _motion_noise
from estimation_nodes.core.kalman import linear as kalman
from estimation_nodes.core.kalman.filter import KalmanFilter
from estimation_nodes.core.kalman.models import (
    GaussianState,
    LinearGaussianModel,
    ScalarKalmanModel,
)
from estimation_nodes.core.tiles import histogram
from estimation_nodes.core.tiles.filter import HistogramFilter
from estimation_nodes.core.tiles.models import (
    HistogramModel,
    MotionKernel,
    SensorModel,
    check_belief,
)
from estimation_nodes.params.grid import default_odometry_noise, default_sensor_field
from tests.unit.test_grid import brute_force_predict

CASES = settings(deadline=None, max_examples=12, derandomize=True)
STEPS = settings(deadline=None, max_examples=40, derandomize=True)

REFUSED = object()
HUGE = (1e300, -1e300, 1.7976931348623157e308, -1.7976931348623157e308)
NOT_FINITE = (math.nan, math.inf, -math.inf)
NOT_NUMBERS = ("abc", None, {"a": 1}, 1 + 2j, b"1", object())


# --- the rule ------------------------------------------------------------------------------


def named(message: str) -> set[str]:
    """The argument names a message starts with ("ranges and angles: ..." -> both)."""
    return set(re.findall(r"[A-Za-z_]\w*", message.split(":", 1)[0]))


def finite(value) -> bool:
    """Whether every number in a result (arrays, tuples, dataclasses) is finite."""
    if isinstance(value, np.ndarray):
        return value.dtype.kind in "biu" or bool(np.isfinite(value).all())
    if value is None or isinstance(value, (bool, int, str, np.integer, np.bool_, enum.Enum)):
        return True
    if isinstance(value, (float, np.floating)):
        return math.isfinite(value)
    if dataclasses.is_dataclass(value):
        return all(finite(getattr(value, f.name)) for f in dataclasses.fields(value))
    if isinstance(value, (tuple, list)):
        return all(finite(v) for v in value)
    raise AssertionError(f"a result of unexpected type {type(value).__name__}: {value!r}")


def obeys(call, names, right=None):
    """Run ``call``: REFUSED if it raised a ValueError naming one of ``names``, else its
    result, checked finite and by ``right``. Any other exception fails the test."""
    names = {names} if isinstance(names, str) else set(names)
    try:
        result = call()
    except ValueError as error:
        assert isinstance(error, errors.EstimationError) or isinstance(error, errors.MapError), \
            f"a ValueError from outside the core's hierarchy: {error!r}"
        assert named(str(error)) & names, f"{error!r} does not name {sorted(names)}"
        return REFUSED
    assert finite(result), f"a result that is not finite: {result!r}"
    # ``right`` asserts, or says False (a lambda of a condition): either fails the test.
    if right is not None:
        assert right(result) is not False, f"a wrong answer: {result!r}"
    return result


def kept(arguments: dict) -> dict:
    """Copies of the arrays among ``arguments``, to check that a call left them alone."""
    return {name: value.copy() for name, value in arguments.items()
            if isinstance(value, np.ndarray)}


def assert_unchanged(arguments: dict, copies: dict) -> None:
    for name, copy in copies.items():
        assert arguments[name].tobytes() == copy.tobytes(), f"{name} was modified"


def same_number(a: float, b: float) -> bool:
    return a == b or (math.isnan(a) and math.isnan(b))


# --- the spoils ----------------------------------------------------------------------------


#: The ways an argument is spoiled; every test runs each (the spoiled argument and the
#: values are drawn). "none" leaves it as it was: a case for the right answer.
KINDS = ("none", "nan", "inf", "huge", "negative", "large", "shape", "empty", "type",
         "complex", "strings", "ragged")


def spoil_array(data, array, kind=None, symmetric=False):
    """``array`` spoiled the ``kind`` way (drawn when None): a NaN, an inf, a huge finite
    value, -1 or 2 in one place (both of a symmetric pair, for a covariance), one value
    more or another shape, empty, no numbers at all, complex, strings of numbers, lists
    of unequal lengths."""
    array = np.array(array, dtype=np.float64)
    kind = kind or data.draw(st.sampled_from(KINDS), label="spoil")
    if kind in ("nan", "inf", "huge", "negative", "large"):
        value = {"nan": st.just(math.nan), "inf": st.sampled_from([math.inf, -math.inf]),
                 "huge": st.sampled_from(HUGE), "negative": st.just(-1.0),
                 "large": st.just(2.0)}[kind]
        spoiled = array.copy()
        index = np.unravel_index(data.draw(st.integers(0, array.size - 1)), array.shape)
        spoiled[index] = data.draw(value, label="value")
        if symmetric:
            spoiled[index[::-1]] = spoiled[index]
        return spoiled
    if kind == "shape":
        return data.draw(st.sampled_from([
            np.concatenate([array, array[:1]]),
            array.reshape(1, -1) if array.ndim == 1 else array.ravel()]), label="shape")
    if kind == "empty":
        return np.zeros((0,) * array.ndim)
    if kind == "type":
        return data.draw(st.sampled_from(NOT_NUMBERS), label="type")
    if kind == "complex":
        return array + 1j
    if kind == "strings":
        return array.astype(str)
    if kind == "ragged":
        return [array.ravel().tolist(), [1.0]]
    return array


def spoil_number(data, value, kind=None):
    """A number spoiled the ``kind`` way (drawn when None): NaN, inf, huge (a float, or an
    integer of 31 digits), negative, fractional or zero, a list or array of it, none,
    no number, complex, a string of it, a ragged list."""
    kind = kind or data.draw(st.sampled_from(KINDS), label="spoil")
    choices = {
        "nan": [math.nan], "inf": [math.inf, -math.inf],
        "huge": list(HUGE) + [10**30, -(10**30)], "negative": [-1.0, -1],
        "large": [2.5, 0.0, 0.5], "shape": [[value], np.array([value, value])],
        "empty": [[], np.zeros(0)], "type": list(NOT_NUMBERS), "complex": [complex(value, 1)],
        "strings": [str(value)], "ragged": [[[value], [value, value]]],
    }.get(kind, [value])
    return data.draw(st.sampled_from(choices), label="spoiled number")


def choose(data, names):
    return data.draw(st.sampled_from(sorted(names)), label="spoiled argument")


# --- tiles: the histogram steps, models and filter, on both paths -----------------------------


def loop_predict(belief, u, weights):
    """The prediction as the book's sum, one cell and one tap at a time."""
    n, half = len(belief), len(weights) // 2
    out = [0.0] * n
    for source in range(n):
        for tap, weight in enumerate(weights):
            out[(source + u + tap - half) % n] += weight * belief[source]
    return np.array(out)


def draw_belief(data, rng, low=1, high=12):
    belief = rng.random(data.draw(st.integers(low, high), label="cells")) + 0.01
    return belief / belief.sum()


def draw_kernel(data, rng):
    weights = rng.random(2 * data.draw(st.integers(0, 3), label="half width") + 1) + 0.01
    return MotionKernel(weights / weights.sum())


@pytest.mark.parametrize("kind", KINDS)
@CASES
@given(data=st.data())
def test_histogram_predict(histogram_path, kind, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    arguments = {"belief": draw_belief(data, rng), "u": data.draw(st.integers(-40, 40)),
                 "kernel": draw_kernel(data, rng)}
    bad = choose(data, arguments)
    if bad == "belief":
        arguments["belief"] = spoil_array(data, arguments["belief"], kind)
    elif bad == "u":
        arguments["u"] = spoil_number(data, arguments["u"], kind)
    else:
        arguments["kernel"] = data.draw(st.sampled_from(
            [arguments["kernel"].weights, [0.1, 0.8, 0.1], None, "kernel"]))
    copies = kept(arguments)

    def right(predicted):
        expected = loop_predict(arguments["belief"], arguments["u"], arguments["kernel"].weights)
        np.testing.assert_allclose(predicted, expected, rtol=0, atol=1e-12)

    obeys(lambda: histogram.predict(**arguments), bad, right)
    assert_unchanged(arguments, copies)


@pytest.mark.parametrize("kind", KINDS)
@CASES
@given(data=st.data())
def test_histogram_correct(histogram_path, kind, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    belief = draw_belief(data, rng)
    arguments = {"belief": belief, "likelihood": rng.uniform(0.05, 1.0, belief.size),
                 "out": belief.copy() if data.draw(st.booleans(), label="out") else None}
    bad = choose(data, arguments)
    if bad == "out":
        read_only = belief.copy()
        read_only.setflags(write=False)
        arguments["out"] = data.draw(st.sampled_from(
            [np.empty(belief.size + 1), np.empty(belief.size, dtype=np.float32), read_only,
             belief.tolist(), "out", np.empty((belief.size, 1))]))
    else:
        arguments[bad] = spoil_array(data, arguments[bad], kind)
    copies = kept(arguments)

    def right(result):
        posterior, evidence = result
        b, likelihood = np.asarray(arguments["belief"]), np.asarray(arguments["likelihood"])
        products = b * likelihood
        np.testing.assert_allclose(evidence, products.sum(), rtol=1e-12)
        np.testing.assert_allclose(posterior, products / products.sum(), rtol=1e-9, atol=1e-300)
        assert posterior.min() >= 0.0

    if obeys(lambda: histogram.correct(**arguments), bad, right) is REFUSED:
        assert_unchanged(arguments, copies)       # out, too, was not written


@pytest.mark.parametrize("kind", KINDS)
@CASES
@given(data=st.data())
def test_histogram_helpers(histogram_path, kind, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    belief = draw_belief(data, rng)
    which = data.draw(st.sampled_from(["uniform", "one_hot size", "one_hot cell",
                                       "most_likely_cell", "entropy"]))
    # A size is memory asked for: a huge one is left out (numpy's MemoryError is its answer).
    small = [-3, 0, 2.5, math.nan, math.inf, "3", None, [3], np.int64(4), True]
    if which == "uniform":
        size = data.draw(st.sampled_from(small))
        obeys(lambda: histogram.uniform(size), "size",
              lambda u: np.testing.assert_allclose(u, np.full(int(size), 1.0 / int(size))))
    elif which.startswith("one_hot"):
        size, cell = 5, 2
        if which.endswith("size"):
            size = data.draw(st.sampled_from(small))
        else:
            cell = spoil_number(data, cell, kind)
        obeys(lambda: histogram.one_hot(size, cell), "size" if which.endswith("size") else "cell",
              lambda b: np.testing.assert_array_equal(b, np.eye(int(size))[int(cell) % int(size)]))
    else:
        spoiled = spoil_array(data, belief, kind)
        copy = kept({"b": spoiled})
        if which == "most_likely_cell":
            obeys(lambda: histogram.most_likely_cell(spoiled), "belief",
                  lambda cell: cell == int(np.argmax(spoiled)))
        else:
            def right(bits):
                positive = np.asarray(spoiled)[np.asarray(spoiled) > 0]
                assert bits == pytest.approx(-(positive * np.log2(positive)).sum(), abs=1e-12)
            obeys(lambda: histogram.entropy(spoiled), "belief", right)
        assert_unchanged({"b": spoiled}, copy)


BOOK_CLASSES = ("bright", "dark")
BOOK_SENSOR = np.array([[0.8, 0.2], [0.4, 0.6]])


@pytest.mark.parametrize("kind", KINDS)
@CASES
@given(data=st.data())
def test_tile_models(kind, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    world = tuple(rng.choice(BOOK_CLASSES, data.draw(st.integers(1, 8))))
    which = data.draw(st.sampled_from(["MotionKernel", "SensorModel", "HistogramModel",
                                       "from_lists", "check_belief"]))
    bad_names = ("bright", "bright", "purple"), [], 5, "bright", None, ("",)
    if which == "MotionKernel":
        weights = spoil_array(data, draw_kernel(data, rng).weights, kind)
        obeys(lambda: MotionKernel(weights), "motion_kernel",
              lambda k: np.testing.assert_allclose(k.weights.sum(), 1.0, atol=1e-9))
    elif which == "SensorModel":
        if data.draw(st.booleans(), label="spoil classes"):
            classes, probabilities, bad = data.draw(st.sampled_from(bad_names)), BOOK_SENSOR, \
                "classes"
        else:
            classes, probabilities, bad = BOOK_CLASSES, spoil_array(data, BOOK_SENSOR, kind), \
                "sensor_model"
        obeys(lambda: SensorModel(classes, probabilities), bad,
              lambda s: np.testing.assert_allclose(s.probabilities.sum(axis=1), 1.0, atol=1e-9))
    elif which == "HistogramModel":
        arguments = {"world": world, "sensor": SensorModel(BOOK_CLASSES, BOOK_SENSOR),
                     "kernel": draw_kernel(data, rng)}
        bad = choose(data, arguments)
        arguments[bad] = data.draw(st.sampled_from(
            bad_names if bad == "world" else [None, "model", BOOK_SENSOR, world]))
        obeys(lambda: HistogramModel(**arguments), bad,
              lambda m: m.size == len(m.world) and finite(m.likelihood("dark")))
    elif which == "from_lists":
        arguments = {"world": world, "classes": BOOK_CLASSES, "sensor_model": BOOK_SENSOR,
                     "kernel": [0.1, 0.8, 0.1]}
        bad = choose(data, arguments)
        if bad in ("world", "classes"):
            arguments[bad] = data.draw(st.sampled_from(bad_names))
        else:
            arguments[bad] = spoil_array(data, arguments[bad], kind)
        message = {"sensor_model": ("sensor_model", "sensor"), "kernel": ("motion_kernel",),
                   "classes": ("classes", "sensor_model", "world")}.get(bad, (bad,))
        obeys(lambda: HistogramModel.from_lists(**arguments), message,
              lambda m: m.size == len(m.world))
    else:
        value = spoil_array(data, draw_belief(data, rng, 4, 4), kind)

        def right(b):
            np.testing.assert_allclose(b, np.asarray(value) / np.sum(value), rtol=1e-12)
        obeys(lambda: check_belief("initial_belief", value, 4), "initial_belief", right)


def filter_state(belief_filter):
    return belief_filter.belief.tobytes(), belief_filter.last_evidence, belief_filter.compiled


@STEPS
@given(data=st.data())
def test_histogram_filter(histogram_path, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    world = tuple(rng.choice(BOOK_CLASSES, data.draw(st.integers(1, 10))))
    model = HistogramModel(world, SensorModel(BOOK_CLASSES, BOOK_SENSOR), draw_kernel(data, rng))
    prior = histogram.uniform(model.size)
    arguments = {"model": model, "initial_belief": prior}
    if data.draw(st.booleans(), label="spoil the construction"):
        bad = choose(data, arguments)
        arguments[bad] = (spoil_array(data, prior) if bad == "initial_belief"
                          else data.draw(st.sampled_from([None, "model", model.sensor])))
        obeys(lambda: HistogramFilter(**arguments).belief, bad)
        return
    belief_filter = HistogramFilter(model, prior, in_place=data.draw(st.booleans()))
    for _ in range(6):
        step = data.draw(st.sampled_from(["predict", "correct", "reconfigure"]))
        before = filter_state(belief_filter)
        if histogram_filter_step(data, belief_filter, model, prior, step) is REFUSED:
            after = filter_state(belief_filter)
            assert after[0] == before[0] and same_number(after[1], before[1]) \
                and after[2] == before[2], f"a refused {step} changed the filter"


def histogram_filter_step(data, belief_filter, model, prior, step):
    """One step of the filter, its input spoiled or not; checked against the steps."""
    belief = belief_filter.belief.copy()
    spoil = data.draw(st.booleans(), label="spoil this step")
    if step == "predict":
        u = spoil_number(data, 1) if spoil else data.draw(st.integers(-20, 20))
        return obeys(lambda: belief_filter.predict(u), "u", lambda b: np.testing.assert_allclose(
            b, loop_predict(belief, u, model.kernel.weights), atol=1e-12))
    if step == "correct":
        observed = (data.draw(st.sampled_from(["purple", 5, None, "", "Dark"])) if spoil
                    else data.draw(st.sampled_from(BOOK_CLASSES)))
        return obeys(lambda: belief_filter.correct(observed), "observation",
                     lambda b: np.testing.assert_allclose(
                         b, histogram.correct(belief, model.likelihood(observed))[0],
                         rtol=1e-12))
    new_prior = spoil_array(data, prior) if spoil else prior
    return obeys(lambda: belief_filter.reconfigure(model, new_prior), "initial_belief")


# --- kalman: the linear steps, the scalar steps, the models and the filter -----------------


def kalman_model(rng, n, m, p):
    return LinearGaussianModel(
        A=np.eye(n) + 0.2 * rng.normal(size=(n, n)), B=rng.normal(size=(n, m)),
        C=rng.normal(size=(p, n)), F=np.eye(n), Q=np.diag(rng.uniform(0.1, 1.0, n)),
        R=np.diag(rng.uniform(0.1, 1.0, p)))


def spd(rng, n):
    root = rng.normal(size=(n, n))
    return root @ root.T + 0.5 * np.eye(n)


def textbook(function, x=None, P=None, u=None, z=None, model=None, gain=None):
    """The steps as Eqs. 6.35 and 6.36 write them, in plain numpy (x, u, z of any shape)."""
    A, B, C, R = model.A, model.B, model.C, model.R
    x = None if x is None else np.ravel(x)
    if function in ("predict", "predicted_mean", "predicted_covariance"):
        x_new = None if x is None else A @ x + B @ np.ravel(u) if u is not None else None
        P_new = None if P is None else A @ P @ A.T + model.F @ model.Q @ model.F.T
        return {"predict": (x_new, P_new), "predicted_mean": x_new,
                "predicted_covariance": P_new}[function]
    S = C @ P @ C.T + R if P is not None else gain.S
    K = P @ C.T @ np.linalg.inv(S) if P is not None else gain.K
    if function == "correction_gain":
        I_KC = np.eye(len(P)) - K @ C
        return K, I_KC @ P @ I_KC.T + K @ R @ K.T
    y = np.ravel(z) - C @ x
    nis = float(y @ np.linalg.solve(S, y))
    if function == "normalized_innovation_squared":
        return nis
    x_new = x + K @ y
    if function == "corrected_mean":
        return x_new, nis
    I_KC = np.eye(len(P)) - K @ C
    P_new = I_KC @ P @ I_KC.T + K @ R @ K.T
    return (x_new, P_new, K) if function == "correct" else (x_new, P_new, K, nis)


def close(actual, expected, scale):
    if isinstance(actual, tuple):
        for a, e in zip(actual, expected):
            close(a, e, scale)
    elif isinstance(actual, kalman.CorrectionGain):
        close((actual.K, actual.P), expected, scale)
    else:
        np.testing.assert_allclose(actual, expected, rtol=1e-7, atol=1e-9 * scale)


KALMAN_STEPS = {
    "predict": ("x", "P", "u", "model"), "predicted_mean": ("x", "u", "model"),
    "predicted_covariance": ("P", "model"), "correction_gain": ("P", "model"),
    "correct": ("x", "P", "z", "model"), "correct_with_nis": ("x", "P", "z", "model"),
    "corrected_mean": ("x", "z", "gain", "model"),
    "normalized_innovation_squared": ("x", "P", "z", "model"),
}


# The public steps let numpy warn of the overflow or NaN they then refuse (linear.py).
@pytest.mark.filterwarnings("ignore:.*encountered in:RuntimeWarning")
@pytest.mark.parametrize("kind", KINDS)
@CASES
@given(data=st.data())
def test_kalman_linear_steps(kind, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    n, m, p = (data.draw(st.integers(1, k)) for k in (4, 2, 3))
    model = kalman_model(rng, n, m, p)
    function = data.draw(st.sampled_from(sorted(KALMAN_STEPS)))
    P = spd(rng, n)
    values = {"x": rng.normal(size=n), "P": P, "u": rng.normal(size=m), "z": rng.normal(size=p),
              "model": model, "gain": kalman.correction_gain(P, model)}
    arguments = {name: values[name] for name in KALMAN_STEPS[function]}
    bad = choose(data, arguments)
    if bad == "model":
        arguments["model"] = data.draw(st.sampled_from([None, "model", ScalarKalmanModel(1, 1)]))
    elif bad == "gain":
        other = kalman_model(rng, n + 1, m, p)
        arguments["gain"] = data.draw(st.sampled_from(
            [None, "gain", kalman.correction_gain(spd(rng, n + 1), other)]))
    else:
        arguments[bad] = spoil_array(data, arguments[bad], kind, symmetric=bad == "P")
    copies = kept(arguments)
    scale = max([1.0] + [float(np.max(np.abs(v))) for v in arguments.values()
                         if isinstance(v, np.ndarray) and v.size and v.dtype.kind == "f"])

    def right(result):
        covariance = {"predict": lambda r: r[1], "predicted_covariance": lambda r: r,
                      "correction_gain": lambda r: r.P, "correct": lambda r: r[1],
                      "correct_with_nis": lambda r: r[1]}.get(function)
        if covariance is not None:       # the steps keep a covariance exactly symmetric
            np.testing.assert_array_equal(covariance(result), covariance(result).T)
        if scale > 1e100:   # overflow-near: the formula's rounding is no oracle, finiteness is
            return
        expected = textbook(function, **{k: (np.asarray(v, dtype=float) if isinstance(
            v, (np.ndarray, list)) else v) for k, v in arguments.items()})
        close(result, expected, scale)

    obeys(lambda: getattr(kalman, function)(**arguments), bad, right)
    assert_unchanged(arguments, copies)


SCALAR_STEPS = {
    "predict_scalar": (kalman.predict_scalar, ("x", "var", "u", "var_u"),
                       lambda x, var, u, var_u: (x + u, var + var_u)),
    "correct_scalar": (kalman.correct_scalar, ("x", "var", "z", "var_z"),
                       lambda x, var, z, var_z: (x + var / (var + var_z) * (z - x),
                                                 (1 - var / (var + var_z)) * var,
                                                 var / (var + var_z))),
    "fuse": (kalman.fuse, ("x1", "var1", "x2", "var2"),
             lambda x1, var1, x2, var2: ((var2 * x1 + var1 * x2) / (var1 + var2),
                                         var1 * var2 / (var1 + var2))),
    "normalized_innovation_squared_scalar": (
        kalman.normalized_innovation_squared_scalar, ("x", "var", "z", "var_z"),
        lambda x, var, z, var_z: (z - x) ** 2 / (var + var_z)),
}


@pytest.mark.parametrize("kind", KINDS)
@CASES
@given(data=st.data())
def test_kalman_scalar_steps(kind, data):
    function, names, formula = SCALAR_STEPS[data.draw(st.sampled_from(sorted(SCALAR_STEPS)))]
    arguments = {name: data.draw(st.floats(0.1, 10.0) if name.startswith("var")
                                 else st.floats(-100.0, 100.0), label=name) for name in names}
    bad = choose(data, arguments)
    arguments[bad] = spoil_number(data, arguments[bad], kind)

    def right(result):
        # Exact rational arithmetic: the answer itself, whatever overflows on the way.
        exact = formula(*(Fraction(float(arguments[name])) for name in names))
        expected = tuple(map(float, exact)) if isinstance(exact, tuple) else float(exact)
        assert result == pytest.approx(expected, rel=1e-12)
        if isinstance(result, tuple) and len(result) > 1:
            assert result[1] >= 0.0                       # a variance stays a variance
    obeys(lambda: function(**arguments), bad, right)


@pytest.mark.parametrize("kind", KINDS)
@CASES
@given(data=st.data())
def test_kalman_models(kind, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    which = data.draw(st.sampled_from(["scalar", "scalar classmethod", "linear", "state"]))
    if which.startswith("scalar"):
        arguments = {"var_u": 2.0, "var_z": 4.0}
        bad = choose(data, arguments)
        arguments[bad] = spoil_number(data, arguments[bad], kind)
        make = LinearGaussianModel.scalar if which.endswith("classmethod") else ScalarKalmanModel
        names = {"var_u": ("var_u", "Q"), "var_z": ("var_z", "R")}[bad]
        obeys(lambda: make(**arguments), names)
    elif which == "linear":
        model = kalman_model(rng, 3, 2, 2)
        arguments = {name: getattr(model, name) for name in "ABCFQR"}
        bad = choose(data, arguments)
        arguments[bad] = spoil_array(data, arguments[bad], kind, symmetric=bad in "QR")
        obeys(lambda: LinearGaussianModel(**arguments), bad,
              lambda m: finite(m.process_noise) and m.state_size == 3)
    else:
        arguments = {"x": rng.normal(size=3), "P": spd(rng, 3)}
        bad = choose(data, arguments)
        arguments[bad] = spoil_array(data, arguments[bad], kind, symmetric=bad == "P")
        # A state of another size than its covariance: either may be named.
        names = ("x0", "P0") if kind in ("shape", "empty") else (bad + "0",)
        obeys(lambda: GaussianState(**arguments), names,
              lambda s: np.min(np.linalg.eigvalsh(s.P)) >= -1e-9 * max(1.0, np.abs(s.P).max()))


def kalman_state(kalman_filter):
    return kalman_filter.x.tobytes(), kalman_filter.P.tobytes(), kalman_filter.last_nis


@STEPS
@given(data=st.data())
def test_kalman_filter(data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    scalar = data.draw(st.booleans(), label="scalar")
    n, m, p = (1, 1, 1) if scalar else (3, 2, 2)
    model = ScalarKalmanModel(2.0, 4.0) if scalar else kalman_model(rng, n, m, p)
    initial = GaussianState(rng.normal(size=n), spd(rng, n))
    if data.draw(st.booleans(), label="spoil the construction"):
        arguments = {"initial": initial, "model": model}
        bad = choose(data, arguments)
        arguments[bad] = data.draw(st.sampled_from([
            None, "x", GaussianState(np.zeros(n + 1), np.eye(n + 1)), kalman_model(rng, 2, 1, 1),
            ScalarKalmanModel(1.0, 1.0)] if not scalar else [None, kalman_model(rng, 2, 1, 1)]))
        obeys(lambda: KalmanFilter(**arguments).P, ("initial", "model"))
        return
    kalman_filter = KalmanFilter(initial, model)
    for _ in range(6):
        step = data.draw(st.sampled_from(["predict", "correct", "prepare", "reconfigure"]))
        before = kalman_state(kalman_filter)
        if kalman_filter_step(data, rng, kalman_filter, initial, step) is REFUSED:
            after = kalman_state(kalman_filter)
            assert after[:2] == before[:2] and same_number(after[2], before[2]), \
                f"a refused {step} changed the filter"
        assert finite((kalman_filter.x, kalman_filter.P, kalman_filter.estimate))


def kalman_filter_step(data, rng, kalman_filter, initial, step):
    """One step of the filter, its input spoiled or not; checked against the steps."""
    model, n = kalman_filter._model, initial.x.size
    scalar = isinstance(model, ScalarKalmanModel)
    x, P = kalman_filter.x.copy(), kalman_filter.P.copy()
    spoil = data.draw(st.booleans(), label="spoil this step")
    if step == "prepare":
        return obeys(kalman_filter.prepare, ())
    if step == "reconfigure":
        other = GaussianState(np.zeros(n + 1), np.eye(n + 1)) if spoil else initial
        return obeys(lambda: kalman_filter.reconfigure(other, model), "initial")
    name, size = ("u", kalman_filter.input_size) if step == "predict" \
        else ("z", kalman_filter.measurement_size)
    value = rng.normal(size=size)
    if spoil:
        value = (spoil_number(data, 1.0) if scalar and data.draw(st.booleans())
                 else spoil_array(data, value))

    def right(estimate):
        if scalar:
            v = float(np.ravel(value)[0]) if np.ndim(value) else float(value)
            expected = (kalman.predict_scalar(x[0], P[0, 0], v, 2.0) if step == "predict"
                        else kalman.correct_scalar(x[0], P[0, 0], v, 4.0)[:2])
        else:
            result = (kalman.predict if step == "predict" else kalman.correct)(x, P, value, model)
            expected = (result[0][0], result[1][0, 0])
        assert (estimate.x, estimate.var) == pytest.approx(expected, rel=1e-12)
    return obeys(lambda: getattr(kalman_filter, step)(value), name, right)


# --- grid: models, steps, helpers and the running localizer, on both paths -----------------


@pytest.fixture(params=["numpy", "compiled"])
def grid_path(request, monkeypatch):
    """Run the test with numpy's passes, then with the compiled kernels at every size."""
    if request.param == "compiled":
        assert _compiled_kernels() is not None, "numba is a dependency; it must import"
        monkeypatch.setattr("estimation_nodes.core.grid.model.COMPILED_MIN_STATES", 1)
    else:
        monkeypatch.setattr("estimation_nodes.core.grid.model.COMPILED_MIN_STATES", sys.maxsize)
    return request.param


def draw_model(data, rng):
    rows, cols = data.draw(st.integers(2, 7), label="rows"), data.draw(st.integers(2, 7))
    free = rng.random((rows, cols)) > 0.25
    free[rows // 2, cols // 2] = True
    return grid.GridModel(free=free, log_field=np.log(0.05 + rng.random((rows, cols))),
                          log_outside=math.log(0.01),
                          resolution=data.draw(st.sampled_from([0.05, 0.1, 0.5])),
                          origin=(float(rng.normal()), float(rng.normal())),
                          heading_bins=data.draw(st.integers(1, 6), label="headings"))


def draw_grid_belief(model, rng):
    belief = (rng.random(model.shape) + 0.01) * model.free[None]
    return belief / belief.sum()


def draw_ranges(data, rng, beams):
    """Ranges of real readings and of extreme finite ones (longer than any map)."""
    return np.array([data.draw(st.sampled_from([float(rng.uniform(0, 1.5)), 0.0, 1e3, 1e6,
                                                1e300, 1.7976931348623157e308]),
                               label="range") for _ in range(beams)])


def brute_force_scan(model, ranges, angles):
    """Every state, every beam: the cell its end point falls in, by exact integer
    arithmetic (Python's ints; an offset that overflows to inf is off the map), and the
    field there."""
    rows, cols = model.free.shape
    theta = model.headings()[:, None] + angles[None, :]
    sin, cos = np.sin(theta), np.cos(theta)
    out = np.zeros(model.shape)
    for k in range(model.heading_bins):
        for b, r in enumerate(ranges):
            with np.errstate(over="ignore"):
                cells = r / model.resolution
            dr, dc = 0.5 + cells * sin[k, b], 0.5 + cells * cos[k, b]
            if not (math.isfinite(dr) and math.isfinite(dc)):
                out[k] += model.log_outside
                continue
            dr, dc = math.floor(dr), math.floor(dc)
            for i in range(rows):
                for j in range(cols):
                    inside = 0 <= i + dr < rows and 0 <= j + dc < cols
                    out[k, i, j] += model.log_field[i + dr, j + dc] if inside \
                        else model.log_outside
    return out


@pytest.mark.parametrize("kind", KINDS)
@CASES
@given(data=st.data())
def test_grid_scan(grid_path, kind, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    model = draw_model(data, rng)
    beams = data.draw(st.integers(1, 5), label="beams")
    function = data.draw(st.sampled_from(["scan_log_likelihood", "correct_scan",
                                          "beam_endpoints"]))
    arguments = {"model": model, "ranges": draw_ranges(data, rng, beams),
                 "angles": rng.uniform(-4, 4, beams)}
    if function == "correct_scan":
        arguments["belief"] = draw_grid_belief(model, rng)
    bad = choose(data, arguments)
    if bad == "model":
        arguments["model"] = data.draw(st.sampled_from([None, "model", model.log_field]))
    else:
        arguments[bad] = spoil_array(data, arguments[bad], kind)
    copies = kept(arguments)
    rows, cols = model.free.shape

    def right(result):
        expected = brute_force_scan(model, np.asarray(arguments["ranges"], dtype=float),
                                    np.asarray(arguments["angles"], dtype=float))
        if function == "scan_log_likelihood":
            np.testing.assert_allclose(result, expected, rtol=0, atol=1e-9)
        elif function == "correct_scan":
            weighted = np.asarray(arguments["belief"]) * np.exp(expected - expected.max())
            np.testing.assert_allclose(result[0], weighted / weighted.sum(), rtol=1e-9,
                                       atol=1e-300)
            assert result[1] == pytest.approx(expected.max() + math.log(weighted.sum()),
                                              rel=1e-9, abs=1e-9)
        else:
            assert result.shape == (model.heading_bins, beams, 2)
            assert np.all(np.abs(result[..., 0]) <= rows)
            assert np.all(np.abs(result[..., 1]) <= cols)

    obeys(lambda: getattr(grid, function)(**arguments), bad, right)
    assert_unchanged(arguments, copies)


def draw_delta(rng, model):
    """A motion of less than a cell: part of each cell's mass stays in it, so some is left
    on a free cell however small the map (a longer one is a spoil of its own)."""
    return (float(rng.uniform(-math.pi, math.pi)), float(rng.uniform(0.0, 0.9 * model.resolution)),
            float(rng.uniform(-math.pi, math.pi)))


@pytest.mark.parametrize("kind", KINDS)
@CASES
@given(data=st.data())
def test_grid_predict(grid_path, kind, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    model = draw_model(data, rng)
    arguments = {"belief": draw_grid_belief(model, rng), "model": model,
                 "delta": draw_delta(rng, model),
                 "noise": grid.OdometryNoise(*rng.uniform(0.0, 0.5, 4))}
    bad = choose(data, arguments)
    if bad == "belief":
        arguments["belief"] = spoil_array(data, arguments["belief"], kind)
    elif bad == "model":
        arguments["model"] = data.draw(st.sampled_from([None, "model", model.free]))
    elif bad == "noise":
        arguments["noise"] = data.draw(st.sampled_from([
            None, "noise", (0.2, 0.2, 0.2, 0.2), grid.OdometryNoise(1e300, 1e300, 1e300, 1e300),
            grid.OdometryNoise(0.0, 0.0, 0.0, 0.0, 0.0, 0.0), grid.OdometryNoise(10, 10, 10, 10),
            grid.OdometryNoise(1e6, 0.0, 1e6, 0.0)]))
    else:
        rot1, trans, rot2 = arguments["delta"]
        arguments["delta"] = data.draw(st.sampled_from([
            (rot1, 1e3, rot2), (rot1, 1e300, rot2), (rot1, 1.7976931348623157e308, rot2),
            (math.nan, trans, rot2), (rot1, math.inf, rot2), (rot1, -0.1, rot2),
            (4.0, trans, rot2), (rot1, trans), (rot1, trans, rot2, 0.0), "delta", None,
            (rot1, trans, 1e300), (math.pi, trans, -math.pi), (rot1, 0.0, rot2)]))
    copies = kept(arguments)

    def right(predicted):
        belief, noise, delta = arguments["belief"], arguments["noise"], arguments["delta"]
        assert predicted.min() >= 0.0 and predicted.sum() == pytest.approx(1.0, abs=1e-12)
        assert np.all(predicted[:, ~model.free] == 0.0)
        numpy_path = grid.predict(belief, model, delta, noise, compiled=False)
        np.testing.assert_allclose(predicted, numpy_path, rtol=0, atol=1e-12)
        sigma_cells, sigma_bins = _motion_noise(delta, noise, model)
        if max(sigma_cells, sigma_bins) < 4:      # taps few enough to visit one by one
            np.testing.assert_allclose(predicted, brute_force_predict(belief, model, delta, noise),
                                       rtol=0, atol=1e-12)
        elif min(sigma_cells, sigma_bins) > 1e9:  # spread evenly: what is left, everywhere
            np.testing.assert_allclose(predicted, grid.uniform_over_free(model), rtol=1e-9)

    obeys(lambda: grid.predict(**arguments), bad, right)
    assert_unchanged(arguments, copies)


@pytest.mark.parametrize("kind", KINDS)
@CASES
@given(data=st.data())
def test_grid_models(kind, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    model = draw_model(data, rng)
    if data.draw(st.booleans(), label="the model, not the noise"):
        arguments = {name: getattr(model, name) for name in
                     ("free", "log_field", "log_outside", "resolution", "origin", "heading_bins")}
        bad = choose(data, arguments)
        if bad == "free":
            arguments["free"] = data.draw(st.sampled_from([
                model.free.astype(np.int8), model.free[:, :-1], np.zeros_like(model.free),
                model.free.tolist(), None, "free", model.free[None]]))
        elif bad == "log_field":
            arguments["log_field"] = spoil_array(data, model.log_field, kind)
        elif bad == "origin":
            arguments["origin"] = data.draw(st.sampled_from([
                (math.nan, 0.0), (0.0,), (0.0, 0.0, 0.0), "xy", None, (1e300, -1e300)]))
        else:
            arguments[bad] = spoil_number(data, arguments[bad], kind)
        names = ("free", "log_field") if bad in ("free", "log_field") else (bad,)

        def right(built):
            assert built.shape == (int(arguments["heading_bins"]), *model.free.shape)
            assert finite(grid.uniform_over_free(built))
        obeys(lambda: grid.GridModel(**arguments), names, right)
    else:
        arguments = dict(zip(("alpha1", "alpha2", "alpha3", "alpha4", "floor_m", "floor_rad"),
                             rng.uniform(0, 1, 6)))
        bad = choose(data, arguments)
        arguments[bad] = spoil_number(data, arguments[bad], kind)
        obeys(lambda: grid.OdometryNoise(**arguments), bad)


GRID_HELPERS = ("gaussian_prior", "covariance_around", "mass_near", "pose_of", "odometry_delta",
                "most_likely_state", "belief_map", "entropy_bits", "correct", "layer_shifts",
                "motion_noise", "gaussian_taps", "uniform_over_free", "refined_pose")


@pytest.mark.parametrize("kind", KINDS)
@CASES
@given(data=st.data())
def test_grid_helpers(grid_path, kind, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    model = draw_model(data, rng)
    belief = draw_grid_belief(model, rng)
    xs, ys = model.cell_centres()
    pose = (float(rng.choice(xs)), float(rng.choice(ys)), float(rng.uniform(-4, 4)))
    function = data.draw(st.sampled_from(GRID_HELPERS))
    arguments = {
        "gaussian_prior": {"model": model, "x": pose[0], "y": pose[1], "yaw": pose[2],
                           "covariance": np.diag(rng.uniform(0.001, 0.5, 3))},
        "covariance_around": {"belief": belief, "model": model, "pose": pose},
        "mass_near": {"belief": belief, "model": model, "pose": pose, "radius": 0.3,
                      "angle": 0.2},
        "pose_of": {"model": model, "state": grid.most_likely_state(belief)},
        "odometry_delta": {"previous": tuple(rng.normal(size=3)),
                           "current": tuple(rng.normal(size=3))},
        "most_likely_state": {"belief": belief}, "belief_map": {"belief": belief},
        "entropy_bits": {"belief": belief},
        "correct": {"belief": belief, "log_likelihood": rng.normal(size=model.shape)},
        "layer_shifts": {"model": model, "rot1": float(rng.uniform(-3, 3)), "trans": 0.3},
        "motion_noise": {"delta": draw_delta(rng, model), "noise": default_odometry_noise(),
                         "model": model},
        "gaussian_taps": {"sigma": float(rng.uniform(0, 5))},
        "uniform_over_free": {"model": model},
        "refined_pose": {"belief": belief, "model": model,
                         "state": grid.most_likely_state(belief)},
    }[function]
    bad = choose(data, arguments)
    value = arguments[bad]
    if bad in ("model", "noise"):
        arguments[bad] = data.draw(st.sampled_from([None, bad, belief, (0.2, 0.2, 0.2, 0.2)]))
    elif isinstance(value, np.ndarray):
        arguments[bad] = spoil_array(data, value, kind, symmetric=bad == "covariance")
    elif isinstance(value, tuple):
        arguments[bad] = data.draw(st.sampled_from([
            (math.nan, *value[1:]), (*value[:-1], math.inf), value[:-1], (*value, 0), "pose",
            None, (1e300, *value[1:]), (-1.7976931348623157e308, *value[1:]),
            tuple(v + 1e3 for v in value), tuple(-v for v in value)]))
    else:
        arguments[bad] = spoil_number(data, value, kind)
    copies = kept(arguments)
    names = {"x": ("x", "y", "covariance"), "y": ("x", "y", "covariance"),
             "yaw": ("yaw", "pose"), "covariance": ("covariance", "x", "y"),
             "previous": ("previous", "current"), "current": ("previous", "current"),
             "delta": ("delta", "noise"), "trans": ("trans",), "rot1": ("rot1",),
             "x_arguments": ()}.get(bad, (bad,))
    if function == "gaussian_prior" and bad in ("x", "y", "yaw"):
        names = names + ("pose",)

    def right(result):
        if function in ("gaussian_prior", "correct", "uniform_over_free"):
            posterior = result[0] if function == "correct" else result
            assert posterior.min() >= 0 and posterior.sum() == pytest.approx(1.0, abs=1e-12)
            if function != "correct":
                assert np.all(posterior[:, ~model.free] == 0)
        elif function == "covariance_around":
            np.testing.assert_array_equal(result, result.T)
            assert np.all(np.diag(result) > 0)
        elif function == "mass_near":
            assert 0.0 <= result <= 1.0 + 1e-12
        elif function == "pose_of":
            k, i, j = arguments["state"]
            assert result[:2] == (xs[j], ys[i])
        elif function == "odometry_delta":
            rot1, trans, rot2 = result
            assert abs(rot1) <= math.pi and abs(rot2) <= math.pi and trans >= 0
        elif function == "most_likely_state":
            assert result == np.unravel_index(np.argmax(arguments["belief"]), model.shape)
        elif function == "belief_map":
            assert result.dtype == np.int8 and 0 <= result.min() and result.max() == 100
        elif function == "entropy_bits":
            p = np.asarray(arguments["belief"])[np.asarray(arguments["belief"]) > 0]
            assert result == pytest.approx(-(p * np.log2(p)).sum(), abs=1e-12)
        elif function == "gaussian_taps":
            assert result.size % 2 == 1 and result.sum() == pytest.approx(1.0)
        elif function == "motion_noise":
            assert min(result) >= 0
        elif function == "refined_pose":
            k, i, j = arguments["state"]
            # Within a cell and a bin of the state's centre, and finite.
            assert abs(result[0] - xs[j]) <= model.resolution + 1e-12
            assert abs(result[1] - ys[i]) <= model.resolution + 1e-12
            assert abs(math.remainder(result[2] - k * model.bin_width, 2 * math.pi)) \
                <= model.bin_width + 1e-12

    obeys(lambda: getattr(grid, function)(**arguments), names, right)
    assert_unchanged(arguments, copies)


def localizer_state(loc):
    return (loc.belief.tobytes(), loc.log_evidence, loc.updates, loc._reference, loc._latest,
            list(loc._history))


def same_state(a, b) -> bool:
    return a[0] == b[0] and same_number(a[1], b[1]) and a[2:] == b[2:]


@STEPS
@given(data=st.data())
def test_grid_localization(grid_path, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    model = draw_model(data, rng)
    settings_ = {"model": model, "noise": default_odometry_noise(), "update_min_d": 0.05,
                 "update_min_a": 0.1, "max_odom_jump": 1.0, "kidnap_probability": 0.01}
    if data.draw(st.booleans(), label="spoil the construction"):
        bad = choose(data, settings_)
        settings_[bad] = (data.draw(st.sampled_from([None, "model", model.free]))
                          if bad in ("model", "noise")
                          else data.draw(st.sampled_from([math.nan, -1.0, "a", None, 2.0])))
        obeys(lambda: GridLocalization(**settings_).belief, bad)
        return
    loc = GridLocalization(**settings_)
    loc.on_odometry((0.0, 0.0, 0.0), 0)
    for stamp in range(10, 90, 10):
        step = data.draw(st.sampled_from(["on_odometry", "on_odometry", "update", "update",
                                          "set_prior", "estimate", "due", "global"]))
        before = localizer_state(loc)
        if localizer_step(data, rng, loc, step, stamp) is REFUSED:
            assert same_state(localizer_state(loc), before), f"a refused {step} changed it"
        assert finite((loc.belief, loc.belief_map(), loc.entropy_bits()))


def localizer_step(data, rng, loc, step, stamp):
    """One call to the localizer, its arguments spoiled or not."""
    spoil = data.draw(st.booleans(), label="spoil this step")
    xs, ys = loc.model.cell_centres()
    if step == "global":
        return obeys(loc.global_localization, ())
    if step == "due":
        value = spoil_number(data, stamp) if spoil else stamp
        return obeys(lambda: (loc.due(value), loc.odometry_covers(value)), "stamp_ns")
    arguments, names, right = {
        "on_odometry": ({"pose": (float(rng.uniform(-0.1, 0.1)), float(rng.uniform(-0.1, 0.1)),
                                  float(rng.uniform(-1, 1))), "stamp_ns": stamp}, {}, None),
        "update": ({"ranges": None, "angles": None, "stamp_ns": None}, {"ranges": ("delta",)},
                   None),
        "set_prior": ({"pose": (float(rng.choice(xs)), float(rng.choice(ys)), 0.5),
                       "covariance": np.diag([0.01, 0.01, 0.1])},
                      {"pose": ("x", "y", "covariance")}, None),
        "estimate": ({"radius": 0.3, "angle": 0.2}, {},
                     lambda e: 0.0 <= e.quality <= 1.0 + 1e-12),
    }[step]
    if step == "update":
        beams = data.draw(st.integers(0, 4))
        arguments["ranges"] = draw_ranges(data, rng, beams)
        arguments["angles"] = rng.uniform(-math.pi, math.pi, beams)
        updates = loc.updates

        def right(_):
            assert loc.updates == updates + 1 and finite(loc.belief)
            assert loc.belief.sum() == pytest.approx(1.0, abs=1e-12)
    bad = choose(data, arguments)
    if spoil:
        value = arguments[bad]
        if bad == "pose":
            arguments[bad] = data.draw(st.sampled_from([
                (math.nan, 0, 0), (0, 0), "pose", (1e300, 0.0, 0.0), (math.inf, 0, 0), None]))
        elif isinstance(value, np.ndarray) and value.size:
            arguments[bad] = spoil_array(data, value, symmetric=bad == "covariance")
        elif isinstance(value, np.ndarray):
            arguments[bad] = data.draw(st.sampled_from([[math.nan], "x", None]))
        else:
            arguments[bad] = spoil_number(data, stamp if value is None else value)
    return obeys(lambda: getattr(loc, step)(**arguments), (bad, *names.get(bad, ())), right)


# --- the issue's crash, and the memory of a long beam ----------------------------------------


def test_an_infinite_range_is_refused_with_its_name_not_a_segmentation_fault(grid_path):
    """Issue 24: update() with an infinite range cast inf to int64 and the compiled kernel
    read outside the padded field."""
    rng = np.random.default_rng(24)
    free = np.ones((20, 20), bool)
    model = grid.GridModel(free, np.log(0.05 + rng.random((20, 20))), math.log(0.01), 0.1,
                           (0.0, 0.0), 36)
    loc = GridLocalization(model, default_odometry_noise(), 0.25, 0.2, 1.0)
    loc.on_odometry((1.0, 1.0, 0.0), 1)
    before = localizer_state(loc)
    for reading in (math.inf, -math.inf, math.nan, -0.5):
        with pytest.raises(errors.InvalidInputError, match=r"^ranges: .* at beam 1"):
            loc.update(np.array([0.5, reading, 1.0]), np.array([0.0, 0.0, 0.3]), 1)
        assert same_state(localizer_state(loc), before)
    loc.update(np.array([0.5, 1e300, 1.0]), np.array([0.0, 0.0, 0.3]), 1)
    assert loc.updates == 1 and loc.belief.sum() == pytest.approx(1.0)


@pytest.mark.parametrize("reading", [1e3, 1e6, 1e300, 1.7976931348623157e308])
def test_a_beam_longer_than_the_map_costs_no_more_memory_than_one_across_it(grid_path, reading):
    """A huge range once asked for a padded field of petabytes; now the padding is the
    map's size at most, whatever the range: the peak is that of a beam just across it."""
    rng = np.random.default_rng(5)
    model = grid.GridModel(np.ones((30, 40), bool), np.log(0.05 + rng.random((30, 40))),
                           math.log(0.01), 0.1, (0.0, 0.0), 8)
    grid.scan_log_likelihood(model, [1.0], [0.0])      # compile, or load, before measuring

    def peak(ranges):
        tracemalloc.start()
        try:
            result = grid.scan_log_likelihood(model, ranges, [0.3, 1.0])
            return tracemalloc.get_traced_memory()[1], result
        finally:
            tracemalloc.stop()

    across, _ = peak([5.0, 5.0])                       # 5 m: past the map's 4 x 3 m
    far, result = peak([reading, 5.0])
    assert far <= 1.2 * across
    np.testing.assert_allclose(result, brute_force_scan(model, np.array([reading, 5.0]),
                                                        np.array([0.3, 1.0])), atol=1e-9)


# --- the likelihood field built from a map ------------------------------------------------------


@pytest.mark.parametrize("kind", KINDS)
@CASES
@given(data=st.data())
def test_likelihood_field_building(kind, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    cells = np.where(rng.random((8, 10)) > 0.3, occupancy.FREE, occupancy.OCCUPIED).astype(np.int8)
    cells[4, 5] = occupancy.FREE
    which = data.draw(st.sampled_from(["OccupancyMap", "SensorField", "log_field",
                                       "grid_model"]))
    if which == "OccupancyMap":
        arguments = {"cells": cells, "resolution": 0.05, "origin": (0.0, 0.0)}
        bad = choose(data, arguments)
        arguments[bad] = data.draw(st.sampled_from(
            [cells.astype(float), cells[0], np.zeros((0, 3), np.int8), "cells", None]
            if bad == "cells" else [(math.nan, 0.0), (0.0,), "xy", None, (1e300, 0.0)]
            if bad == "origin" else [math.nan, -0.05, 0.0, "0.05", None, 1e300]))
        obeys(lambda: occupancy.OccupancyMap(**arguments), "map" if bad == "cells" else bad)
    elif which == "SensorField":
        arguments = {"z_hit": 0.5, "z_rand": 0.5, "sigma_hit": 0.2, "max_range": 12.0,
                     "max_distance": 2.0}
        bad = choose(data, arguments)
        arguments[bad] = spoil_number(data, arguments[bad], kind)
        names = ("z_hit", "z_rand") if bad in ("z_hit", "z_rand") else (bad,)
        obeys(lambda: likelihood_field.SensorField(**arguments), names)
    elif which == "log_field":
        sensor = default_sensor_field()
        distance = spoil_array(data, rng.uniform(0, 3, (4, 5)), kind)
        bound = math.log(sensor.z_hit + sensor.z_rand / sensor.max_range)
        obeys(lambda: likelihood_field.log_field(distance, sensor), "distance",
              lambda field: np.all(field <= bound + 1e-12))
    else:
        arguments = {"occupancy": occupancy.OccupancyMap(cells, 0.05, (0.0, 0.0)),
                     "resolution": 0.1, "heading_bins": 8, "sensor": default_sensor_field(),
                     "max_states": 10_000}
        bad = choose(data, arguments)
        if bad in ("occupancy", "sensor"):
            arguments[bad] = data.draw(st.sampled_from([None, cells, "map"]))
        else:
            arguments[bad] = spoil_number(data, arguments[bad], kind)
        names = {"occupancy": ("occupancy", "sensor"), "sensor": ("occupancy", "sensor"),
                 "heading_bins": ("heading_bins", "max_states"),
                 "resolution": ("resolution", "map")}.get(bad, (bad,))
        obeys(lambda: likelihood_field.grid_model(**arguments), names,
              lambda model: model.shape[1:] == (4, 5))


# --- wrong answers the spoils found -------------------------------------------------------------


def test_a_prior_far_wider_than_the_measurement_keeps_a_variance():
    """(1 - w) var was 0 from var / var_z ~ 1e16 on (w rounds to 1): a filter certain for
    ever after one measurement. The variance is var var_z / (var + var_z)."""
    for var in (1e16, 1e17, 1e100, 1e300):
        x, variance, gain = kalman.correct_scalar(0.0, var, 3.0, 4.0)
        assert variance == pytest.approx(var * 4.0 / (var + 4.0), rel=1e-12)
        assert x == pytest.approx(3.0) and gain == pytest.approx(1.0)
    kalman_filter = KalmanFilter(GaussianState(np.zeros(1), np.array([[1e20]])),
                                 ScalarKalmanModel(1.0, 4.0))
    kalman_filter.correct(3.0)
    kalman_filter.correct(5.0)                    # the second measurement still counts
    assert kalman_filter.estimate.x == pytest.approx(4.0)
    assert kalman_filter.estimate.var == pytest.approx(2.0)


def test_fusing_a_huge_variance_is_the_other_estimate_not_an_overflow():
    estimate = kalman.fuse(1.0, 1.7976931348623157e308, 2.0, 2.0)
    assert estimate == pytest.approx((2.0, 2.0))


def test_a_huge_log_likelihood_on_a_ruled_out_state_leaves_the_evidence_of_the_others():
    """The weights were taken from the largest log likelihood anywhere: one of 1e300 on a
    state of zero probability made every other weight underflow, and the correction said
    that every state rules the scan out."""
    belief = np.array([0.0, 0.25, 0.75])
    log_likelihood = np.array([1e300, 0.0, math.log(2.0)])
    posterior, log_evidence = grid.correct(belief, log_likelihood)
    np.testing.assert_allclose(posterior, [0.0, 0.25 / 1.75, 1.5 / 1.75])
    assert log_evidence == pytest.approx(math.log(0.25 + 1.5))
