"""The contract every weather effect keeps, checked for every registry entry (and variants)."""

from __future__ import annotations

import dataclasses
import json
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from weather_cases import VARIANT_IDS, VARIANTS, build

from weather_gym.weather import EFFECTS, Compose, KnobEffect, Ramp, make
from weather_gym.weather.base import DEFAULT_SEED

FAST = settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
STATE = {"speed": 12.0, "yaw_rate": 0.4, "exposure_s": 0.02, "fx": 300.0}


def _images(h_max=40, w_min=1, w_max=90):
    return st.tuples(st.integers(1, h_max), st.integers(w_min, w_max), st.integers(0, 2**16))


def _random_image(h, w, seed):
    return np.random.default_rng(seed).integers(0, 256, (h, w, 3), dtype=np.uint8)


@pytest.mark.parametrize(("name", "params"), VARIANTS, ids=VARIANT_IDS)
class TestEveryEffect:
    @FAST
    @given(size=_images(), k=st.floats(0.0, 1.0))
    def test_output_is_a_new_uint8_image_and_input_untouched(self, name, params, size, k):
        img = _random_image(*size)
        before = img.copy()
        out = build(name, params, k)(img, rng=np.random.default_rng(1))
        assert out.dtype == np.uint8 and out.shape == img.shape
        assert not np.shares_memory(out, img)
        np.testing.assert_array_equal(img, before)

    @FAST
    @given(size=_images())
    def test_k_zero_is_the_identity_to_the_byte(self, name, params, size):
        img = _random_image(*size)
        out = build(name, params, 0.0)(img, depth=np.full(img.shape[:2], 5.0, np.float32), state=STATE)
        np.testing.assert_array_equal(out, img)

    @FAST
    @given(size=_images(30, 80, 120), k=st.floats(0.05, 1.0), seed=st.integers(0, 99))
    def test_same_seed_same_bytes(self, name, params, size, k, seed):
        img = _random_image(*size)
        a, b = build(name, params, k), build(name, params, k)
        a.reset(seed)
        b.reset(seed)
        for _ in range(2):
            np.testing.assert_array_equal(a(img), b(img))
        np.testing.assert_array_equal(build(name, params, k)(img, rng=np.random.default_rng(seed)),
                                      build(name, params, k)(img, rng=np.random.default_rng(seed)))

    def test_default_seed_without_reset_is_repeatable(self, name, params, scene):
        img, _ = scene
        a, b = build(name, params, 0.7), build(name, params, 0.7)
        np.testing.assert_array_equal(a(img), b(img))
        c = build(name, params, 0.7)
        c.reset(DEFAULT_SEED)
        np.testing.assert_array_equal(c(img), build(name, params, 0.7)(img))

    def test_reset_restarts_the_episode(self, name, params, scene):
        img, depth = scene
        e = build(name, params, 0.6)
        e.reset(11)
        first = [e(img, depth=depth, state=STATE) for _ in range(3)]
        e.reset(11)
        again = [e(img, depth=depth, state=STATE) for _ in range(3)]
        for x, y in zip(first, again, strict=True):
            np.testing.assert_array_equal(x, y)

    def test_non_contiguous_input_gives_the_same_result(self, name, params, scene):
        img, depth = scene
        view = np.asfortranarray(img)[:, ::-1][:, ::-1]
        assert not view.flags.c_contiguous
        a = build(name, params, 0.5)(img, depth=depth, rng=np.random.default_rng(2))
        b = build(name, params, 0.5)(view, depth=depth, rng=np.random.default_rng(2))
        np.testing.assert_array_equal(a, b)

    def test_batch_equals_frame_by_frame(self, name, params, scenes):
        frames = np.stack([s[0] for s in scenes] * 2)
        depths = np.stack([s[1] for s in scenes] * 2)
        e1, e2 = build(name, params, 0.6), build(name, params, 0.6)
        batch = e1(frames, depth=depths, state=STATE, rng=np.random.default_rng(4))
        rng = np.random.default_rng(4)
        loop = np.stack([e2(f, depth=d, state=STATE, rng=rng) for f, d in zip(frames, depths, strict=True)])
        assert batch.shape == frames.shape and batch.dtype == np.uint8
        np.testing.assert_array_equal(batch, loop)

    def test_batch_takes_one_state_per_frame(self, name, params, scenes):
        frames = np.stack([s[0] for s in scenes])
        out = build(name, params, 0.5)(frames, state=[STATE, {}], rng=np.random.default_rng(0))
        assert out.shape == frames.shape
        with pytest.raises(ValueError, match="one state mapping or 2"):
            build(name, params, 0.5)(frames, state=[STATE])

    def test_params_round_trip_and_serialise(self, name, params):
        e = build(name, params, 0.42)
        p = e.params()
        assert p["k"] == 0.42 and all(p[key] == v for key, v in params.items())
        json.dumps(p)  # plain types only (TOML has no null: none may be None)
        assert all(isinstance(v, bool | int | float | str) for v in p.values())
        again = make(name, **p)
        assert again == e and again.params() == p

    def test_bad_input_is_a_clear_value_error(self, name, params):
        e = build(name, params, 0.5)
        img = np.zeros((8, 9, 3), np.uint8)
        cases = [
            (img.astype(np.float32), "uint8"),
            (np.zeros((8, 9, 4), np.uint8), "3 RGB channels"),
            (np.zeros((8, 9), np.uint8), "3 RGB channels"),
            (np.zeros((0, 9, 3), np.uint8), ">= 1"),
            ([[1, 2, 3]], "numpy uint8 array"),
        ]
        for bad, msg in cases:
            with pytest.raises(ValueError, match=msg):
                e(bad)
        with pytest.raises(ValueError, match=r"depth must have shape \(8, 9\)"):
            e(img, depth=np.zeros((9, 8), np.float32))
        with pytest.raises(ValueError, match="depth must be a float array"):
            e(img, depth=np.zeros((8, 9), np.uint16))
        with pytest.raises(ValueError, match="state\\['speed'\\] must be finite"):
            e(img, state={"speed": float("nan")})
        with pytest.raises(ValueError, match="rng must be a numpy.random.Generator"):
            e(img, rng=np.random.RandomState(0))
        with pytest.raises(ValueError, match="seed must be"):
            e.reset(-1)

    def test_bad_parameters_are_named(self, name, params):
        for k in (-0.1, 1.5, float("nan"), "0.5", True):
            with pytest.raises(ValueError, match=f"{name}: parameter k="):
                build(name, params, k)
        cls = EFFECTS.get(name)
        for f in dataclasses.fields(cls):
            if f.name == "k" or f.name in cls.CHOICES:
                continue
            bad = "yes" if f.type == "bool" else float("nan")
            with pytest.raises(ValueError, match=f"parameter {f.name}="):
                make(name, k=0.5, **{f.name: bad})
        with pytest.raises(ValueError, match="unknown parameter"):
            make(name, k=0.5, not_a_parameter=1)


@pytest.mark.parametrize("name", EFFECTS.names())
def test_every_numeric_parameter_has_a_range_and_its_ends_are_valid(name):
    cls = EFFECTS.get(name)
    assert issubclass(cls, KnobEffect) and cls.name == name
    fields = {f.name: f for f in dataclasses.fields(cls)}
    assert set(cls.PARAM_BOUNDS) <= set(fields) and set(cls.PARAM_LIMITS) <= set(fields)
    assert "k" not in cls.PARAM_BOUNDS
    for pname, f in fields.items():
        if f.type in ("float", "int"):
            lo, hi = cls.bounds_of(pname)
            assert lo < hi
            make(name, k=0.5, **({} if pname == "k" else {pname: lo}))
            make(name, k=0.5, **({} if pname == "k" else {pname: hi}))
            if pname != "k":
                with pytest.raises(ValueError, match="outside"):
                    make(name, k=0.5, **{pname: hi + abs(hi) + 1})


def test_effects_are_immutable_and_hashable():
    e = make("dim", k=0.3)
    with pytest.raises(dataclasses.FrozenInstanceError):
        e.k = 0.5
    assert hash(e) == hash(make("dim", k=0.3)) and e != make("dim", k=0.31)


def test_depth_and_state_are_accepted_by_every_effect(scene):
    img, depth = scene
    for name in EFFECTS:
        out = make(name, k=0.5)(img, depth=depth.astype(np.float64), state=STATE, rng=np.random.default_rng(0))
        assert out.shape == img.shape


@pytest.mark.parametrize("weather", [
    Compose([make("droplets", k=0.5), make("noise", k=0.4), make("dim", k=0.2)]),
    Ramp("dim", 0.0, 0.9, steps=3),
], ids=["compose", "ramp"])
def test_compose_and_ramp_keep_the_contract(weather, scene):
    img, depth = scene
    before = img.copy()
    weather.reset(3)
    a = [weather(img, depth=depth) for _ in range(3)]
    weather.reset(3)
    b = [weather(img, depth=depth) for _ in range(3)]
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
        assert x.dtype == np.uint8 and x.shape == img.shape and not np.shares_memory(x, img)
    np.testing.assert_array_equal(img, before)
    with pytest.raises(ValueError, match="uint8"):
        weather(img.astype(np.int16))


def test_empty_compose_is_an_exact_copy(noisy_image):
    out = Compose([])(noisy_image)
    np.testing.assert_array_equal(out, noisy_image)
    assert not np.shares_memory(out, noisy_image)


def test_no_global_rng_is_touched(scene):
    img, _ = scene
    before = np.random.get_state()[1].copy()  # noqa: NPY002 - checking the legacy global state
    for name in EFFECTS:
        make(name, k=0.7)(img)
    np.testing.assert_array_equal(np.random.get_state()[1], before)  # noqa: NPY002


def test_the_weather_layer_imports_only_numpy_opencv_and_the_stdlib():
    import ast
    from pathlib import Path

    import weather_gym.weather as pkg

    allowed = {"numpy", "cv2", "weather_gym", "PIL", "__future__", "tomli"}
    kernels = {name: {"numba"} for name in ("_drop_blend.py", "_noise_pass.py", "_near_blend.py",
                                            "_night_isp.py", "_area.py")}  # compiled passes, each loaded with the first
    # frame that needs it
    kernels["augment.py"] = {"albumentations"}  # the optional Albumentations adapter: imported only by its users
    kernels["base.py"] = {"pydantic", "pydantic_core"}  # the effects' declared parameter schemas (param_schema)
    for path in Path(pkg.__file__).parent.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import | ast.ImportFrom):
                names = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
                for name in names:
                    top = name.split(".")[0]
                    assert top in allowed | kernels.get(path.name, set()) or top in sys.stdlib_module_names, \
                        f"{path.name} imports {name}"
                    if top == "weather_gym":
                        assert name.startswith(("weather_gym.weather", "weather_gym.core.registry", "weather_gym.core.errors",
                                                "weather_gym.core.limits", "weather_gym.core._jit_cache")), \
                            f"{path.name} imports {name} (the weather layer depends on nothing else)"


@pytest.mark.parametrize("light, compiled", [("droplets:0.5", "droplets:0.5:mode=refractive"),
                                             ("dim:0.5", "dim:0.5:mode=night"), ("dim:0.5", "noise:0.5"),
                                             ("fog:0.5", "motion_blur:0.5")])
def test_numba_loads_only_when_a_compiled_pass_draws_a_frame(light, compiled):
    """The weather layer stays light to import: numba (about 1.3 s) comes with the first frame of an effect
    that has a compiled pass (the refractive drops' blend, the sensor noise, the motion smear's blend), not
    with building one."""
    import subprocess

    code = (f"import sys, numpy as np; from weather_gym.weather import parse_weather; e = parse_weather({compiled!r});"
            f"parse_weather({light!r})(np.zeros((40, 60, 3), np.uint8), rng=np.random.default_rng(0));"
            "print('numba' in sys.modules, end=' '); e(np.zeros((40, 60, 3), np.uint8), rng=np.random.default_rng(0));"
            "print('numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "True"]
