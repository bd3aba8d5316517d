"""Property-based fuzz suite (hypothesis): garbage in gives named errors, valid pairs obey the
identities every form factor must.

Garbage input (None, bools, strings, NaN, inf, huge or tiny numbers, ragged and wrongly shaped
arrays, odd objects) to every public entry point must either be accepted and give a sane result
or raise a ValueError (the core's promise; `checks.ArgumentTypeError` is both a TypeError and a
ValueError) raised by core code with a message of its own, never a raw numpy/Python message,
another exception class, a NaN or a hang.

On random valid pairs (every kind, kept to pairs where at least one side has an exact or
analytic inner integral so that each example takes well under a second):

- 0 <= F <= 1 within its error estimate;
- reciprocity A_i F_ij = A_j F_ji (Siegel & Howell, Thermal Radiation Heat Transfer, eq. 4.19);
- closure: sum_j F_ij = 1 for an object inside a closed sphere or cube (the summation rule);
- invariance under rigid motions with translations up to 1e4 and under uniform scaling
  1e-6 ... 1e6 (a form factor is dimensionless and frame-free);
- the batch `form_factors` equals the single `form_factor`.

Every test is derandomized (a fixed example sequence: the same run on every machine), keeps no
example database, bounds each example with a deadline and the number of examples, and prints
the failing example (hypothesis does) so that it can be replayed as a plain test.
"""

import math
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, note, settings
from hypothesis import strategies as st

import core

CORE_DIR = Path(core.__file__).resolve().parent
TOL = 1e-4  # loose, so that each example is fast; the identities are checked to a few tol

# fixed seed, no database, bounded time (bounded inputs and example counts; no per-example
# deadline: a timing assertion would fail on a loaded machine, speed is for the benchmarks)
FUZZ = settings(
    derandomize=True,
    database=None,
    deadline=None,
    max_examples=40,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much, HealthCheck.data_too_large],
    print_blob=True,
)
QUICK = settings(FUZZ, max_examples=150)
PAIRS = settings(FUZZ, max_examples=3)  # per kind of the first surface
BATCH = settings(FUZZ, max_examples=12)
CLOSURE = settings(FUZZ, max_examples=3)  # per kind inside

# messages Python or numpy produce themselves: an error carrying one of them names nothing
RAW_MESSAGES = re.compile(
    "|".join(
        [
            r"could not convert",
            r"cannot convert float",
            r"int\(\) argument",
            r"float\(\) argument",
            r"unsupported operand",
            r"object of type .* has no len",
            r"is not subscriptable",
            r"is not iterable",
            r"object is not callable",
            r"setting an array element with a sequence",
            r"zero-size array to reduction",
            r"operands could not be broadcast",
            r"invalid literal",
            r"takes \d+ positional argument",
            r"unexpected keyword argument",
            r"only integer scalar arrays",
            r"must be real number, not",
            r"math domain error",
        ]
    )
)


# ---------------------------------------------------------------------------- error contract
def raised_in_core(exc):
    """Whether the innermost frame of exc's traceback lies in core/ (the core named it)."""
    tb = exc.__traceback__
    last = None
    while tb is not None:
        last = tb.tb_frame.f_code.co_filename
        tb = tb.tb_next
    return last is not None and Path(last).resolve().is_relative_to(CORE_DIR)


def call_or_named_error(call):
    """Run call(); return (True, result) or (False, exception) if it raised a named ValueError.

    Any other exception, or a ValueError raised outside core/ or carrying a raw Python/numpy
    message, fails the test with the exception attached.
    """
    try:
        return True, call()
    except ValueError as exc:  # (ArgumentTypeError and ConvergenceError are ValueErrors)
        message = str(exc)
        assert message, f"{type(exc).__name__} without a message"
        assert raised_in_core(exc), f"{type(exc).__name__} from outside core/: {message}"
        assert not RAW_MESSAGES.search(message), f"raw message, names nothing: {message}"
        return False, exc


# ---------------------------------------------------------------------------- garbage
finite = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False)
odd_floats = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e-320, 1e-200, 1e-40, 1e40, 1e200, 1e308, -1.0, np.nan, np.inf, -np.inf]),
)
odd_ints = st.one_of(
    st.integers(min_value=-(10**30), max_value=10**30), st.sampled_from([0, -1, 2**63, 10**400])
)
junk = st.one_of(
    st.none(),
    st.booleans(),
    st.text(max_size=4),
    st.sampled_from(
        ["1.0", "nan", "", "x", b"1", 1j, object(), {}, set(), (), [], [[]], np.array([]), Ellipsis]
    ),
    st.complex_numbers(allow_nan=True, allow_infinity=True),
)
scalar_garbage = st.one_of(odd_floats, odd_ints, junk, st.lists(odd_floats, max_size=3))


def vectors_garbage(n=3):
    """Anything a user might pass where an n-vector belongs, valid or not."""
    return st.one_of(
        st.lists(odd_floats, min_size=n, max_size=n),
        st.lists(st.one_of(odd_floats, junk), min_size=0, max_size=n + 2),
        st.lists(st.lists(finite, max_size=3), max_size=3),  # ragged or nested
        scalar_garbage,
        st.lists(finite, min_size=n, max_size=n).map(np.array),
        st.lists(finite, min_size=n, max_size=n).map(lambda x: np.array(x, dtype=np.float32)),
        st.lists(st.integers(-5, 5), min_size=n, max_size=n).map(lambda x: np.array(x, dtype=np.int8)),
    )


def maybe(valid, garbage):
    """A strategy drawing a valid value most of the time and garbage otherwise."""
    return st.one_of(valid, valid, garbage)


unit_vector = st.lists(finite, min_size=3, max_size=3).filter(lambda x: np.linalg.norm(x) > 1e-3)
point3 = st.lists(finite, min_size=3, max_size=3)
size = st.floats(min_value=1e-3, max_value=1e3)


def sane_surface(surface):
    """A surface a constructor accepted: positive finite area, finite points and normals."""
    area = surface.area()
    assert math.isfinite(area) and area > 0.0, f"accepted {surface!r} with area {area!r}"
    (u0, u1), (v0, v1) = surface.domain
    u, v = np.meshgrid(np.linspace(u0, u1, 4), np.linspace(v0, v1, 4))
    x, n = surface.evaluate(u.ravel(), v.ravel())
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(n)), f"{surface!r} evaluates to non-finite values"


def fuzz_entry(call, valid, garbage, words, check=None, runs=QUICK, min_accepted=3, min_rejected=10):
    """Fuzz one entry point: each example corrupts one argument (or none) with garbage.

    Parameters
    ----------
    call : callable(**arguments)
    valid, garbage : dict of name -> strategy
        Valid values and garbage for every argument (garbage may happen to be valid).
    words : dict of name -> sequence of str
        A rejection with argument `name` corrupted must mention one of these words (the error
        names the argument it is about).
    check : callable(result, arguments), optional
        Sanity check of an accepted call's result.
    runs : hypothesis settings
    min_accepted, min_rejected : int
        The examples must have covered at least this many accepted and rejected calls.
    """
    tally = {True: 0, False: 0}
    names = sorted(valid)

    @runs
    @given(data=st.data())
    def run(data):
        # about a third of the examples are wholly valid (their results are checked)
        corrupt = data.draw(st.sampled_from([None] * max(1, len(names) // 2) + names), label="corrupt")
        arguments = {
            name: data.draw(garbage[name] if name == corrupt else valid[name], label=name) for name in names
        }
        ok, result = call_or_named_error(lambda: call(**arguments))
        tally[ok] += 1
        if ok:
            if check is not None:
                check(result, arguments)
        else:
            message = str(result).lower()
            if corrupt is None:
                raise AssertionError(f"valid arguments {arguments!r} rejected: {result}")
            assert any(w in message for w in words[corrupt]), (
                f"garbage in {corrupt} = {arguments[corrupt]!r} raised an error not naming it: {result}"
            )

    run()
    assert tally[True] >= min_accepted and tally[False] >= min_rejected, f"coverage: {tally}"


def test_garbage_sphere():
    fuzz_entry(
        lambda center, radius: core.Sphere(center, radius),
        dict(center=point3, radius=size),
        dict(center=vectors_garbage(), radius=scalar_garbage),
        dict(center=["center", "from the origin"], radius=["radius"]),
        check=lambda s, _: sane_surface(s),
    )


def test_garbage_quad():
    names = ["p00", "p10", "p11", "p01"]
    square = dict(p00=(0, 0, 0), p10=(1, 0, 0), p11=(1, 1, 0), p01=(0, 1, 0))
    fuzz_entry(
        lambda **c: core.Quad(*(c[k] for k in names)),
        {
            k: st.lists(st.floats(-0.2, 0.2), min_size=3, max_size=3).map(lambda d, k=k: np.add(square[k], d))
            for k in names
        },
        {k: vectors_garbage() for k in names},
        # (a valid corner that makes the quad degenerate is named by the quad's shape)
        {k: [k, "quad size", "area", "folds"] for k in names},
        check=lambda s, _: sane_surface(s),
        min_rejected=20,
    )


def test_garbage_disk():
    fuzz_entry(
        lambda center, normal, radius: core.Disk(center, normal, radius),
        dict(center=point3, normal=unit_vector, radius=size),
        dict(center=vectors_garbage(), normal=vectors_garbage(), radius=scalar_garbage),
        dict(center=["center", "from the origin"], normal=["normal"], radius=["radius"]),
        check=lambda s, _: sane_surface(s),
    )


def test_garbage_cylinder():
    fuzz_entry(
        lambda base, axis, radius, height: core.Cylinder(base, axis, radius, height),
        dict(base=point3, axis=unit_vector, radius=size, height=size),
        dict(base=vectors_garbage(), axis=vectors_garbage(), radius=scalar_garbage, height=scalar_garbage),
        dict(base=["base_center", "from the origin"], axis=["axis"], radius=["radius"], height=["height"]),
        check=lambda s, _: sane_surface(s),
    )


def clamped_knots(n, k):
    """Open uniform knot vector for n points of order k, shape (n + k,)."""
    return np.r_[np.zeros(k), np.linspace(0, 1, n - k + 2)[1:-1], np.ones(k)]


NET = np.stack(
    [*np.meshgrid(np.linspace(0, 1, 4), np.linspace(0, 1, 3), indexing="ij"), 0.2 * np.eye(4, 3)], -1
)  # (4, 3, 3)


def test_garbage_nurbs():
    fuzz_entry(
        lambda points, weights, order_u, order_v, knots_u, knots_v: core.NurbsSurface(
            points, weights, order_u, order_v, knots_u, knots_v
        ),
        dict(
            points=st.just(NET),
            weights=st.just(np.ones((4, 3))) | st.just(np.linspace(0.5, 2, 12).reshape(4, 3)),
            order_u=st.just(3),
            order_v=st.just(3),
            knots_u=st.just(clamped_knots(4, 3)),
            knots_v=st.just(clamped_knots(3, 3)),
        ),
        dict(
            points=vectors_garbage()
            | st.sampled_from([NET[..., :2], NET[:, :1], np.where(NET == 0.2, np.nan, NET), NET * 1e200]),
            weights=scalar_garbage
            | st.sampled_from(
                [
                    -np.ones((4, 3)),
                    np.ones((4, 1)),
                    np.full((4, 3), 1e-300),
                    np.full((4, 3), 1e300),
                    np.eye(4, 3),
                ]
            ),
            order_u=scalar_garbage | st.integers(-3, 8),
            order_v=scalar_garbage | st.integers(-3, 8),
            knots_u=vectors_garbage(7)
            | st.sampled_from(
                [
                    clamped_knots(4, 3)[::-1],
                    np.zeros(7),
                    clamped_knots(4, 3)[:-1],
                    clamped_knots(4, 3) * 1e-300,
                ]
            ),
            knots_v=vectors_garbage(6) | st.sampled_from([np.zeros(6), np.arange(6.0)[::-1]]),
        ),
        dict(
            points=["points", "area"],
            weights=["weights", "area"],
            order_u=["order_u"],
            order_v=["order_v"],
            knots_u=["knots_u", "domain"],
            knots_v=["knots_v", "domain"],
        ),
        check=lambda s, _: sane_surface(s),
        runs=FUZZ,
    )


def base_pair():
    return core.Sphere((0, 0, 6), 1.0), core.Quad((-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0))


def form_factor_check(value, arguments):
    assert 0.0 <= value <= 1.0, f"F = {value!r} for {arguments!r}"


def test_garbage_form_factor():
    sphere, square = base_pair()
    fuzz_entry(
        lambda src, dst, tol, method, order, occluders: core.form_factor(
            src, dst, tol=tol, method=method, order=order, occluders=occluders
        ),
        dict(
            src=st.sampled_from([sphere, square]),
            dst=st.sampled_from([square, sphere]),
            tol=st.floats(1e-3, 0.5),
            method=st.just("adaptive"),
            order=st.none(),
            occluders=st.sampled_from([None, []]),
        ),
        dict(
            src=junk | scalar_garbage,
            dst=junk | scalar_garbage,
            tol=scalar_garbage,
            method=junk | scalar_garbage | st.sampled_from(["Adaptive", "gauss"]),
            order=scalar_garbage | st.integers(-3, 4),
            occluders=junk | scalar_garbage | st.just(sphere) | st.lists(junk, min_size=1, max_size=2),
        ),
        dict(
            src=["src"],
            dst=["dst"],
            tol=["tol"],
            method=["method", "order"],
            order=["order"],
            occluders=["occluders"],
        ),
        check=form_factor_check,
    )


def test_garbage_form_factors():
    sphere, square = base_pair()
    lists = st.lists(st.sampled_from([sphere, square]), min_size=1, max_size=2)
    lists_garbage = (
        junk | scalar_garbage | st.lists(junk | st.sampled_from([sphere, square]), min_size=1, max_size=3)
    )

    def check(F, arguments):
        F = np.asarray(F)
        assert F.shape == (len(arguments["sources"]), len(arguments["targets"]))
        assert np.all(np.isfinite(F)) and np.all((F >= 0.0) & (F <= 1.0)), F

    fuzz_entry(
        lambda sources, targets, tol: core.form_factors(sources, targets, tol=tol),
        dict(sources=lists, targets=lists, tol=st.floats(1e-3, 0.5)),
        dict(sources=lists_garbage, targets=lists_garbage, tol=scalar_garbage),
        dict(sources=["sources"], targets=["targets"], tol=["tol"]),
        check=check,
    )


SURFACES = {
    "sphere": core.Sphere((0, 0, 0), 1.0),
    "quad": core.Quad((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)),
    "disk": core.Disk((0, 0, 0), (0, 0, 1), 1.0),
    "cylinder": core.Cylinder((0, 0, 0), (0, 0, 1), 1.0, 2.0),
    "nurbs": core.NurbsSurface(NET, np.ones((4, 3)), 3, 3, clamped_knots(4, 3), clamped_knots(3, 3)),
}
surface_names = st.sampled_from(sorted(SURFACES))


def test_garbage_split():
    def check(parts, arguments):
        surface = SURFACES[arguments["surface"]]
        assert len(parts) == arguments["nu"] * arguments["nv"]
        assert sum(p.area() for p in parts) == pytest.approx(surface.area(), rel=1e-6)

    # (valid counts stay small: a NURBS split validates every piece, ~1.4 ms each here)
    counts = st.one_of(
        junk,
        odd_floats,
        st.integers(-(10**30), 0),
        st.integers(10**6 + 1, 10**30),
        st.sampled_from([2.5, 3.0, np.int64(2), np.float32(2.0), 10**7, 2**63, 10**400]),
    )
    fuzz_entry(
        lambda surface, nu, nv: SURFACES[surface].split(nu, nv),
        dict(surface=surface_names, nu=st.integers(1, 4), nv=st.integers(1, 4)),
        dict(surface=surface_names, nu=counts, nv=counts),
        dict(surface=[], nu=["nu", "patches"], nv=["nv", "patches"]),
        check=check,
    )


matrix_garbage = st.one_of(
    st.lists(st.lists(odd_floats, min_size=4, max_size=4), min_size=4, max_size=4),
    vectors_garbage(16),
    st.lists(st.lists(finite, min_size=3, max_size=5), min_size=2, max_size=5),
    st.sampled_from(
        [
            np.zeros((4, 4)),
            np.diag([1e200, 1e200, 1e200, 1.0]),
            np.diag([1e-200, 1.0, 1.0, 1.0]),
            np.diag([1e-40, 1e-40, 1e-40, 1.0]),
            np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1.0]]),
            np.array([[1, 0, 0, 1e300], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]]),
            np.array([[1, 1, 0, 0], [1, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]]),
        ]
    ),
)


def test_garbage_transformed():
    fuzz_entry(
        lambda surface, matrix: SURFACES[surface].transformed(matrix),
        dict(
            surface=surface_names,
            matrix=st.tuples(quaternions, st.floats(-2.0, 2.0), point3).map(
                lambda t: affine(10.0 ** t[1] * rotation(t[0]), t[2])[:3]
            ),
        ),
        dict(surface=surface_names, matrix=matrix_garbage),
        dict(surface=[], matrix=["matrix", "transform"]),
        check=lambda s, _: sane_surface(s),
        min_rejected=5,
    )


def test_garbage_subpatch():
    def limits(name):
        return st.tuples(st.floats(0.0, 0.45), st.floats(0.55, 1.0)).map(
            lambda t: tuple(a + t_ * (b - a) for t_ in t for (a, b) in [SURFACES[name].domain[0]])
        )

    fuzz_entry(
        lambda surface, u: SURFACES["quad"].subpatch(u=u),
        dict(surface=st.just("quad"), u=st.none() | limits("quad")),
        dict(
            surface=st.just("quad"),
            u=vectors_garbage(2) | st.tuples(finite, finite) | st.just((0.5, 0.5 + 1e-17)),
        ),
        dict(surface=[], u=["u"]),
        check=lambda s, _: sane_surface(s),
    )


def small_scene():
    scene = core.Scene()
    ball = scene.add(core.Sphere((0, 0, 6), 1.0), emission=1.0, patches=(2, 2))
    scene.add(core.Quad((-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)), patches=(2, 2))
    return scene, ball


def test_garbage_scene_add():
    def add(surface, reflectance, emission, patches, name, two_sided, occluder):
        scene, _ = small_scene()
        return scene.add(
            surface,
            reflectance=reflectance,
            emission=emission,
            patches=patches,
            name=name,
            two_sided=two_sided,
            occluder=occluder,
        )

    fuzz_entry(
        add,
        dict(
            surface=st.just(core.Disk((0, 0, 3), (0, 0, -1), 0.5)),
            reflectance=st.floats(0.0, 0.95) | st.lists(st.floats(0.0, 0.95), min_size=3, max_size=3),
            emission=st.floats(0.0, 10.0),
            patches=st.none() | st.tuples(st.integers(1, 3), st.integers(1, 3)) | st.integers(1, 3),
            name=st.none() | st.text(max_size=5),
            two_sided=st.booleans(),
            occluder=st.booleans(),
        ),
        dict(
            surface=junk | scalar_garbage,
            reflectance=scalar_garbage | vectors_garbage() | st.just(1.0),
            emission=scalar_garbage | vectors_garbage(),
            patches=scalar_garbage | vectors_garbage(2) | st.just((10**4, 10**4)),
            name=junk.filter(lambda x: x is not None and not isinstance(x, str)) | scalar_garbage,
            two_sided=scalar_garbage | st.sampled_from([0, 1, "True"]),
            occluder=scalar_garbage | st.sampled_from([0, 1, "False"]),
        ),
        dict(
            surface=["surface"],
            reflectance=["reflectance"],
            emission=["emission"],
            patches=["patches"],
            name=["name"],
            two_sided=["two_sided"],
            occluder=["occluder"],
        ),
        check=lambda handle, _: handle == 2 or pytest.fail(f"handle {handle!r}"),
    )


def test_garbage_scene_solve():
    def solve(tol, occlusion, max_bounces, method, cull, threads):
        scene, ball = small_scene()
        return scene.solve(
            tol=tol, occlusion=occlusion, max_bounces=max_bounces, method=method, cull=cull, threads=threads
        ), ball

    def check(result, arguments):
        solution, ball = result
        B = solution.radiosity(ball)
        assert np.all(np.isfinite(B)) and np.all(B >= 0.0), B

    fuzz_entry(
        solve,
        dict(
            tol=st.floats(1e-3, 0.3),
            occlusion=st.sampled_from([True, False, "exact", "sampled"]),
            max_bounces=st.none() | st.integers(0, 5) | st.just(10**9),
            method=st.sampled_from([None, "jacobi"]),  # (max_bounces counts Jacobi sweeps)
            cull=st.sampled_from([True, False, {"facing", "rows"}]),
            threads=st.none() | st.integers(1, 2),
        ),
        dict(
            tol=scalar_garbage,
            occlusion=junk | scalar_garbage | st.sampled_from(["EXACT", "none"]),
            max_bounces=scalar_garbage,
            method=junk | scalar_garbage | st.sampled_from(["lu", "direct", "gmres", "iterative"]),
            cull=junk | scalar_garbage | st.just({"facnig"}),
            threads=scalar_garbage | st.just(10**6),
        ),
        dict(
            tol=["tol"],
            occlusion=["occlusion"],
            max_bounces=["max_bounces"],
            method=["method"],
            cull=["cull"],
            threads=["threads"],
        ),
        check=check,
        runs=FUZZ,
    )


@st.composite
def blender_nets(draw):
    """A NURBS net as Blender's surface objects give one: 4 x 4 points (a bumped sheet, random
    weights), each direction's order 2-4 and its cyclic / endpoint / Bezier flags at random (the
    flags that fold a net onto itself included)."""
    z = draw(st.lists(st.floats(-0.6, 0.6), min_size=16, max_size=16))
    w = draw(st.lists(st.floats(0.5, 2.0), min_size=16, max_size=16))
    grid = [(x, y) for y in (-1.5, -0.5, 0.5, 1.5) for x in (-1.5, -0.5, 0.5, 1.5)]
    points = np.array([(x, y, h, weight) for (x, y), h, weight in zip(grid, z, w)])
    flags = draw(st.lists(st.booleans(), min_size=6, max_size=6))
    orders = draw(st.lists(st.integers(2, 4), min_size=2, max_size=2))
    names = (
        "use_cyclic_u",
        "use_cyclic_v",
        "use_endpoint_u",
        "use_endpoint_v",
        "use_bezier_u",
        "use_bezier_v",
    )
    return points, orders, dict(zip(names, flags))


@pytest.mark.parametrize("method", ["pairs", "hierarchical"])
def test_blender_nets_solve_or_are_refused_by_name(method):
    """Every net Blender can make, solved under a lamp on either path: finite, non-negative
    radiosity on both sides, or a ValueError the core names (a flag Blender itself refuses, a net
    that lies on itself: `core.CrossingSurfaceError`), never a silent 1e305 (the hierarchical path
    returned that for folded nets) or a warning."""

    @settings(FUZZ, max_examples=10)
    @given(net=blender_nets())
    def run(net):
        points, (order_u, order_v), flags = net
        note(f"orders {order_u}, {order_v}, {flags}")

        def solve():
            surface = core.NurbsSurface.from_blender(points, order_u, order_v, 4, 4, **flags)
            scene = core.Scene()
            handle = scene.add(surface, reflectance=0.8, patches=(2, 2), two_sided=True)
            scene.add_point_light((0.3, 0.2, 4.0), 200.0 / (4 * np.pi))
            solution = scene.solve(tol=1e-2, method=method)
            return np.concatenate([solution.radiosity(handle), solution.radiosity(handle, side="back")])

        solved, B = call_or_named_error(solve)
        if solved:
            # (the net lies within its points' hull, z <= 0.6, so the lamp's irradiance is at
            # most I / 3.4^2 = 1.4; reflected with rho = 0.8 and every bounce: B <= 1.4 / 0.2)
            assert np.all(np.isfinite(B)) and np.all(B >= 0.0) and 0.0 < B.max() <= 7.0, B

    run()


SOLVED = []


def solved_small_scene():
    if not SOLVED:
        scene, ball = small_scene()
        SOLVED.append((scene.solve(tol=1e-2), ball))
    return SOLVED[0]


def test_garbage_radiosity_at():
    solution, _ = solved_small_scene()
    coordinates = st.lists(st.floats(0.0, 1.0), min_size=2, max_size=2)

    def check(B, arguments):
        B = np.asarray(B)
        assert B.shape == (2, 3) and np.all(np.isfinite(B)) and np.all(B >= 0.0), B

    fuzz_entry(
        lambda handle, u, v, side: solution.radiosity_at(handle, u, v, side=side),
        dict(handle=st.just(1), u=coordinates, v=coordinates, side=st.just("front")),
        dict(
            handle=scalar_garbage | st.integers(-3, 5) | st.just(True),
            u=vectors_garbage(2) | st.just([2.0, 0.5]),
            v=vectors_garbage(2) | st.just([0.5]),
            side=junk | scalar_garbage | st.sampled_from(["Front", "back"]),
        ),
        dict(handle=["handle"], u=["u", "domain"], v=["v", "domain"], side=["side", "back"]),
        check=check,
    )


# ---------------------------------------------------------------------------- valid pairs
def rotation(q):
    """Rotation matrix from a non-zero quaternion (w, x, y, z), shape (3, 3)."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def affine(linear=np.eye(3), offset=(0.0, 0.0, 0.0)):
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = linear, offset
    return m


quaternions = st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(lambda q: np.linalg.norm(q) > 0.1)
ANALYTIC = ["sphere", "sphere_patch", "quad", "triangle", "disk", "annulus", "cylinder"]
GENERIC = ["ellipsoid", "twisted_quad", "nurbs"]  # no exact inner integral: paired with ANALYTIC only


@st.composite
def shapes(draw, kinds):
    """A unit-sized surface of one of `kinds`, centred near the origin, in a random orientation.

    Returns (surface, kind, radius of a ball about the origin holding it).
    """
    kind = draw(st.sampled_from(kinds))
    s = draw(st.floats(0.5, 1.0))
    if kind == "sphere":
        surface = core.Sphere((0, 0, 0), s)
    elif kind == "sphere_patch":
        u0 = draw(st.floats(0.0, 2.0))
        v0 = draw(st.floats(0.0, 4.5))
        surface = core.Sphere((0, 0, 0), s).subpatch(
            u=(u0, min(np.pi, u0 + draw(st.floats(0.3, 1.5)))), v=(v0, v0 + draw(st.floats(0.3, 1.5)))
        )
    elif kind in ("quad", "triangle", "twisted_quad"):
        jitter = draw(st.lists(st.floats(-0.25, 0.25), min_size=8, max_size=8))
        xy = np.array([(-1, -1), (1, -1), (1, 1), (-1, 1)], dtype=float) + np.reshape(jitter, (4, 2))
        z = np.zeros(4) if kind != "twisted_quad" else np.array([-1, 1, -1, 1]) * draw(st.floats(0.1, 0.4))
        corners = np.column_stack([xy, z]) * s
        if kind == "triangle":
            corners[3] = corners[0]
        surface = core.Quad(*corners)
    elif kind == "disk":
        surface = core.Disk((0, 0, 0), (0, 0, 1), s)
    elif kind == "annulus":
        surface = core.Disk((0, 0, 0), (0, 0, 1), s).subpatch(u=(draw(st.floats(0.1, 0.7)) * s, s))
    elif kind == "cylinder":
        surface = core.Cylinder((0, 0, -0.5 * s), (0, 0, 1), 0.5 * s, s)
    elif kind == "ellipsoid":
        axes = draw(st.lists(st.floats(0.3, 1.0), min_size=3, max_size=3))
        surface = core.Sphere((0, 0, 0), 1.0).transformed(affine(np.diag(axes) * s))
    else:  # nurbs: a bi-quadratic bump over the unit square, rational or not
        z = np.reshape(draw(st.lists(st.floats(-0.4, 0.4), min_size=9, max_size=9)), (3, 3))
        w = np.reshape(draw(st.lists(st.floats(0.5, 2.0), min_size=9, max_size=9)), (3, 3))
        x, y = np.meshgrid([-1.0, 0.0, 1.0], [-1.0, 0.0, 1.0], indexing="ij")
        knots = [0, 0, 0, 1, 1, 1]
        surface = core.NurbsSurface(np.stack([x, y, z], -1) * s, w, 3, 3, knots, knots)
    if draw(st.booleans()) and kind not in ("sphere", "ellipsoid", "cylinder"):
        surface = surface.flipped()
    surface = surface.transformed(affine(rotation(draw(quaternions))))
    (u0, u1), (v0, v1) = surface.domain
    u, v = np.meshgrid(np.linspace(u0, u1, 9), np.linspace(v0, v1, 9))
    x, _ = surface.evaluate(u.ravel(), v.ravel())
    return surface, kind, float(np.linalg.norm(x, axis=1).max())


@st.composite
def pairs(draw, first, partners=None):
    """A surface of kind `first` and one of a random kind (at most one GENERIC), their bounding
    balls apart.

    The gap between the balls is 0.05 ... 3 times the larger radius; the second surface is
    turned to face the first when it is flat and faces away (otherwise most flat pairs are 0).

    Returns (a, b, kind of a, kind of b).
    """
    a, kind_a, ra = draw(shapes([first]))
    if partners is None:
        partners = ANALYTIC if kind_a in GENERIC else ANALYTIC + GENERIC
    b, kind_b, rb = draw(shapes(partners))
    direction = np.asarray(draw(unit_vector), dtype=float)
    direction /= np.linalg.norm(direction)
    gap = draw(st.floats(0.05, 3.0)) * max(ra, rb)
    b = b.transformed(affine(offset=direction * (ra + rb + gap)))
    a, b = facing(a, kind_a, b), facing(b, kind_b, a)
    note(f"pair: {kind_a} {a!r} -> {kind_b} {b!r}")
    return a, b, kind_a, kind_b


def facing(surface, kind, other):
    """`surface`, flipped if it is open and faces away from `other` at all its sample points."""
    if kind in ("sphere", "ellipsoid", "cylinder"):
        return surface
    (u0, u1), (v0, v1) = surface.domain
    u, v = np.meshgrid(np.linspace(u0, u1, 5), np.linspace(v0, v1, 5))
    x, n = surface.evaluate(u.ravel(), v.ravel())
    y, _ = other.evaluate(np.array([np.mean(other.domain[0])]), np.array([np.mean(other.domain[1])]))
    return surface.flipped() if np.all(np.einsum("ki,ki->k", n, y - x) <= 0.0) else surface


def estimate(a, b, tol=TOL):
    return core.form_factor_estimate(a, b, tol=tol)


def close(x, y, scale, tol=TOL, slack=3.0):
    """|x - y| within slack * tol of `scale` (both sides met tol relative to their values)."""
    return abs(x - y) <= slack * tol * scale + 1e-15


class Coverage:
    """What the examples of a property test covered: kinds seen and non-zero factors."""

    def __init__(self):
        self.kinds = set()
        self.nonzero = 0
        self.examples = 0

    def add(self, kinds, value):
        self.kinds.update(kinds)
        self.nonzero += value > 0.0
        self.examples += 1

    def check(self, kinds=ANALYTIC + GENERIC, nonzero=0.5):
        missing = set(kinds) - self.kinds
        assert not missing, f"the examples never drew {sorted(missing)}"
        assert self.nonzero >= nonzero * self.examples, f"only {self.nonzero} of {self.examples} factors > 0"


@pytest.mark.parametrize("first", ANALYTIC + GENERIC)
def test_form_factor_bounded_and_reciprocal(first):
    seen = Coverage()

    @PAIRS
    @given(pair=pairs(first))
    def run(pair):
        a, b, kind_a, kind_b = pair
        ab, ba = estimate(a, b), estimate(b, a)
        for e in (ab, ba):
            assert math.isfinite(e.value) and math.isfinite(e.error)
            assert -e.error <= e.value <= 1.0 + e.error, e
            assert e.error <= TOL * e.value + 1e-15, f"error estimate above tol: {e}"
        flux_ab, flux_ba = a.area() * ab.value, b.area() * ba.value
        assert close(flux_ab, flux_ba, max(flux_ab, flux_ba)), (
            f"reciprocity: A_a F_ab = {flux_ab!r}, A_b F_ba = {flux_ba!r} ({ab}, {ba})"
        )
        seen.add((kind_a, kind_b), ab.value)

    run()
    seen.check(kinds=[first], nonzero=0.25)


@pytest.mark.parametrize("first", ANALYTIC + GENERIC)
def test_rigid_motion_invariance(first):
    seen = Coverage()

    @PAIRS
    @given(pair=pairs(first), q=quaternions, offset=st.lists(st.floats(-1e4, 1e4), min_size=3, max_size=3))
    def run(pair, q, offset):
        a, b, kind_a, kind_b = pair
        F = estimate(a, b).value
        m = affine(rotation(q), offset)
        F_moved = estimate(a.transformed(m), b.transformed(m)).value
        assert close(F, F_moved, F), f"F = {F!r}, after the motion {F_moved!r}"
        seen.add((kind_a, kind_b), F)

    run()
    seen.check(kinds=[first], nonzero=0.25)


@pytest.mark.parametrize("first", ANALYTIC + GENERIC)
def test_uniform_scaling_invariance(first):
    """F is unchanged by a uniform scaling about the origin: at 1e-6, 1e6 and a drawn scale."""
    seen = Coverage()

    @PAIRS
    @given(pair=pairs(first), exponent=st.floats(-6.0, 6.0))
    def run(pair, exponent):
        a, b, kind_a, kind_b = pair
        F = estimate(a, b).value
        for e in (-6.0, 6.0, exponent):
            m = affine(10.0**e * np.eye(3))
            F_scaled = estimate(a.transformed(m), b.transformed(m)).value
            assert close(F, F_scaled, F), f"F = {F!r}, scaled by 1e{e:.2f}: {F_scaled!r}"
        seen.add((kind_a, kind_b), F)

    run()
    seen.check(kinds=[first], nonzero=0.25)


def test_batch_equals_single():
    seen = Coverage()

    @BATCH
    @given(
        sources=st.lists(
            st.sampled_from(ANALYTIC + GENERIC).flatmap(lambda kind: pairs(kind, ANALYTIC)),
            min_size=1,
            max_size=2,
        )
    )
    def run(sources):
        # pair k moved 20 k along x: the crossed entries (a_i -> b_j, i != j) are far apart (well
        # posed and quick) and have at most one generic side, like the drawn pairs themselves
        moved = [
            (a.transformed(affine(offset=(20.0 * k, 0, 0))), b.transformed(affine(offset=(20.0 * k, 0, 0))))
            for k, (a, b, *_) in enumerate(sources)
        ]
        row = [p[0] for p in moved]
        column = [p[1] for p in moved]
        F = core.form_factors(row, column, tol=TOL)
        assert F.shape == (len(row), len(column))
        for i, src in enumerate(row):
            for j, dst in enumerate(column):
                single = core.form_factor(src, dst, tol=TOL)
                assert close(F[i, j], single, max(F[i, j], single)), (i, j, F[i, j], single)
        for k, p in enumerate(sources):
            seen.add(p[2:], F[k, k])

    run()
    seen.check(kinds=())


# ---------------------------------------------------------------------------- closure
CONVEX_FRONT = ["sphere", "sphere_patch", "quad", "triangle", "disk", "annulus", "cylinder", "ellipsoid"]


@st.composite
def inside(draw, room, first):
    """A surface with a convex front (it sees none of itself) at a random place inside a ball of
    radius `room` about the origin. Returns (surface, kind)."""
    surface, kind, r = draw(shapes([first]))
    if kind == "sphere_patch" and surface.orientation < 0:
        surface = surface.flipped()  # (the inside of a sphere patch sees itself)
    scale = draw(st.floats(0.05, 0.5)) * room / r
    direction = np.asarray(draw(unit_vector), dtype=float)
    direction /= np.linalg.norm(direction)
    offset = direction * draw(st.floats(0.0, 0.9)) * (room - scale * r)
    note(f"inside: {kind}")
    return surface.transformed(affine(scale * np.eye(3), offset)), kind


@pytest.mark.parametrize("first", CONVEX_FRONT)
def test_closure_inside_sphere(first):
    """Sum_j F(obj -> j) over the patches of the enclosing sphere (seen from inside) is 1."""
    seen = Coverage()

    @CLOSURE
    @given(obj=inside(1.0, first), nu=st.integers(1, 3), nv=st.integers(1, 3))
    def run(obj, nu, nv):
        surface, kind = obj
        enclosure = core.Sphere((0, 0, 0), 1.0).flipped().split(nu, nv)
        row = core.form_factors([surface], enclosure, tol=TOL)
        assert abs(row.sum() - 1.0) <= 3.0 * TOL, f"sum F = {row.sum()!r}: {row}"
        seen.add([kind], row.sum())

    run()
    seen.check(kinds=[first], nonzero=1.0)


def cube_faces(half):
    """The six faces of the cube [-half, half]^3, fronts facing in."""
    h = half
    faces = []
    for axis in range(3):
        for side in (-1.0, 1.0):
            e1, e2 = np.eye(3)[(axis + 1) % 3], np.eye(3)[(axis + 2) % 3]
            c = side * h * np.eye(3)[axis]
            corners = [c - h * e1 - h * e2, c + h * e1 - h * e2, c + h * e1 + h * e2, c - h * e1 + h * e2]
            quad = core.Quad(*corners)
            faces.append(quad if np.dot(np.cross(e1, e2), -c) > 0 else quad.flipped())
    return faces


@pytest.mark.parametrize("first", CONVEX_FRONT)
def test_closure_inside_cube(first):
    """Sum_j F(obj -> face j) over the six inward faces of a cube around it is 1."""
    seen = Coverage()
    half = 1.0

    @CLOSURE
    @given(obj=inside(half, first))  # (the ball of radius `half` touches the faces from inside)
    def run(obj):
        surface, kind = obj
        row = core.form_factors([surface], cube_faces(half), tol=TOL)
        assert abs(row.sum() - 1.0) <= 3.0 * TOL, f"sum F = {row.sum()!r}: {row}"
        seen.add([kind], row.sum())

    run()
    seen.check(kinds=[first], nonzero=1.0)


# ---------------------------------------------------------------------------- smooth-pair rule
SMOOTH_KINDS = ["sphere", "quad", "triangle", "disk", "annulus"]


def facing_up(kind, s):
    """A unit-sized surface of `kind` in the plane z = 0 (a sphere: centred there), front +z."""
    if kind == "sphere":
        return core.Sphere((0, 0, 0), 0.5 * s)
    if kind in ("quad", "triangle"):
        c = np.array([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], dtype=float) * 0.5 * s
        if kind == "triangle":
            c[3] = c[0]
        return core.Quad(*c)
    disk = core.Disk((0, 0, 0), (0, 0, 1), 0.5 * s)
    return disk if kind == "disk" else disk.subpatch(u=(0.2 * s, 0.5 * s))


@st.composite
def facing_pairs(draw, first):
    """`first` below, a SMOOTH_KINDS partner 1.5 ... 4 sizes above it facing down, tilted by up
    to 0.3 rad and shifted sideways by up to half a size: the pairs the smooth rule takes."""
    a = facing_up(first, draw(st.floats(0.5, 1.0)))
    b = facing_up(draw(st.sampled_from(SMOOTH_KINDS)), draw(st.floats(0.5, 1.0))).flipped()
    tilt = rotation([1.0, draw(st.floats(-0.15, 0.15)), draw(st.floats(-0.15, 0.15)), 0.0])
    shift = [draw(st.floats(-0.5, 0.5)), draw(st.floats(-0.5, 0.5)), draw(st.floats(1.5, 4.0))]
    if isinstance(b, core.Sphere):
        b = b.flipped()  # (a whole sphere faces out)
    return a, b.transformed(affine(tilt, shift))


@pytest.mark.parametrize("first", SMOOTH_KINDS)
def test_smooth_rule_agrees_with_adaptive(first, monkeypatch):
    """Pairs done by one outer Gauss rule of increasing order (`formfactor.SMOOTH_ORDERS`) agree
    with the adaptive method (the rule switched off) within tol, and their estimate covers the
    difference, at tol 1e-8."""
    from core import formfactor

    tol = 1e-8
    used = []

    # (8 examples: the full suite once drew a set of 4 of which the rule took only 1, in a run
    # where the file alone draws sets it takes 2-3 of; 5 of the first 8 with a sphere below)
    @settings(FUZZ, max_examples=8)
    @given(pair=facing_pairs(first))
    def run(pair):
        a, b = pair
        smooth = core.form_factor_estimate(a, b, tol=tol)
        with monkeypatch.context() as m:
            m.setattr(formfactor, "SMOOTH_ORDERS", ())
            adaptive = core.form_factor_estimate(a, b, tol=tol)
        gap = abs(smooth.value - adaptive.value)
        assert gap <= smooth.error + adaptive.error + 1e-15, (smooth, adaptive)
        assert gap <= 2.0 * tol * max(smooth.value, adaptive.value) + 1e-15, (smooth, adaptive)
        used.append(smooth.evaluations != adaptive.evaluations)

    run()
    assert sum(used) >= 2, f"the smooth-pair rule took {sum(used)} of {len(used)} examples"
